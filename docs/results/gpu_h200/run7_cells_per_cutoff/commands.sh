#!/usr/bin/env bash
# Cells per cut-off on the GPU: the binary before (pairsum_base) and after with 1, 2 and 4 cells.
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
chmod +x .gpubin/pairsum .gpubin/pairsum_base
o=/tmp/o; mkdir -p $o
nvidia-smi --query-gpu=name,memory.total,clocks.max.memory --format=csv > $o/machine.txt; nproc >> $o/machine.txt
one() { # cfg name case resolution steps end extra...
  local cfg=$1 n=$2 c=$3 r=$4 s=$5 e=$6; shift 6
  local b=pairsum k=${cfg#k}
  if [ "$cfg" = base ]; then b=pairsum_base; k=; fi
  local start=$(date +%s%N)
  PAIRSUM_GPU_CELLS_PER_CUTOFF=$k timeout 60 .gpubin/$b run $c --resolution $r --backend gpu --precision f32 --max-steps $s --end-time $e --out /tmp/r --quiet "$@" > $o/$n.stdout.txt 2>&1
  echo "exit $? total_ms $(( ($(date +%s%N) - start) / 1000000 ))" >> $o/$n.stdout.txt
  cp /tmp/r/report.json $o/$n.report.json; cp /tmp/r/histories.csv $o/$n.histories.csv; [ -f /tmp/r/timing.txt ] && cp /tmp/r/timing.txt $o/$n.timing.txt; rm -rf /tmp/r
  echo "$n $(tail -1 $o/$n.stdout.txt)"
}
for cfg in base k1 k2 k4; do
  one $cfg ${cfg}__dam_break_3d.gpu_short dam_break_3d gpu 30 0.11 --set integrator=symplectic_pec
  one $cfg ${cfg}__dam_break_3d.gpu_long dam_break_3d gpu 90 0.11 --set integrator=symplectic_pec
done
for cfg in base k1 k2 k4; do
  one $cfg ${cfg}__pysph_impact3d.gpu_short pysph_impact3d 0.25mm 40 1e-6
  one $cfg ${cfg}__pysph_impact3d.gpu_long pysph_impact3d 0.25mm 120 1e-6
done
for cfg in base k1 k2; do
  one $cfg ${cfg}__dam_break_2d.gpu_short dam_break_2d 0.1mm 100 0.28
  one $cfg ${cfg}__dam_break_2d.gpu_long dam_break_2d 0.1mm 300 0.28
done
one k2 k2_timing_dam_break_3d dam_break_3d gpu 60 0.11 --set integrator=symplectic_pec --timing
one base base_timing_dam_break_3d dam_break_3d gpu 60 0.11 --set integrator=symplectic_pec --timing
tar czf $OUT/all.tgz -C $o .
