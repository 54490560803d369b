#!/usr/bin/env bash
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
gunzip -k -f .gpubin/before.gz .gpubin/after.gz; chmod +x .gpubin/before .gpubin/after
o=/tmp/ab; mkdir -p $o
nvidia-smi --query-gpu=name,memory.total,clocks.max.memory --format=csv > $o/machine.txt 2>&1
one() { # bin case res steps end tag
  local at=$o/$2_$3.$1.$4.$6
  timeout 120 .gpubin/$1 run $2 --resolution $3 --backend gpu --precision f32 --max-steps $4 --end-time $5 --out /tmp/r --quiet --force --timing > $at.stdout.txt 2>&1
  echo "exit $?" >> $at.stdout.txt
  cp /tmp/r/histories.csv $at.histories.csv 2>/dev/null; cp /tmp/r/timing.txt $at.timing.txt 2>/dev/null
  rm -rf /tmp/r; echo "$at $(head -2 $at.timing.txt | tail -1)"
}
for rep in 1 2; do for b in before after; do
  one $b dam_break_3d gpu 200 0.11 r$rep
  one $b pysph_impact3d 0.25mm 200 1e-4 r$rep
  one $b dam_break_2d 0.1mm 300 0.28 r$rep
done; done
tar czf $OUT/ab2.tgz -C /tmp ab
