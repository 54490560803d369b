#!/usr/bin/env bash
# after: parameters of i hoisted; new: + reads of the globals in the submission that computes them; prof: new + host timers.
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
for b in before after new prof; do gunzip -k -f .gpubin/$b.gz; chmod +x .gpubin/$b; done
o=/tmp/ab3; mkdir -p $o
nvidia-smi --query-gpu=name,memory.total,clocks.max.memory --format=csv > $o/machine.txt 2>&1
one() { # bin case res steps end tag [extra...]
  local b=$1 c=$2 r=$3 n=$4 e=$5 tag=$6; shift 6
  local at=$o/${c}_$r.$b.$n.$tag
  timeout 120 .gpubin/$b run $c --resolution $r --backend gpu --precision f32 --max-steps $n --end-time $e --out /tmp/r --quiet --force "$@" > $at.stdout.txt 2>&1
  echo "exit $?" >> $at.stdout.txt
  cp /tmp/r/histories.csv $at.histories.csv 2>/dev/null; cp /tmp/r/timing.txt $at.timing.txt 2>/dev/null
  rm -rf /tmp/r; echo "$at $(head -2 $at.timing.txt 2>/dev/null | tail -1)"
}
for rep in 1 2; do for b in after new; do
  one $b dam_break_2d 0.1mm 300 0.28 r$rep --timing
  one $b pysph_impact3d 0.25mm 200 1e-4 r$rep --timing
  one $b sod_shock_tube ci 400 0.2 r$rep --timing
done; done
for b in before new; do one $b dam_break_3d gpu 200 0.11 pec --timing --set integrator=symplectic_pec; done
one prof dam_break_2d 0.1mm 300 0.28 prof
one prof pysph_impact3d 0.25mm 200 1e-4 prof
one prof sod_shock_tube ci 400 0.2 prof
one prof dam_break_3d gpu 100 0.11 prof
for f in $o/*.prof.stdout.txt; do echo "$f $(grep PROF $f | awk '{r+=$3; f+=$5; s+=$7; w+=$9; n++} END {print "record", r/n, "finish", f/n, "submit", s/n, "wait", w/n, "us over", n}')"; done | tee $o/prof_summary.txt
tar czf $OUT/ab3.tgz -C /tmp ab3
