#!/usr/bin/env bash
# final (HEAD) against loopfree (the same, shaders compiled without naga's loop bounding).
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
for b in final loopfree; do gunzip -k -f .gpubin/$b.gz; chmod +x .gpubin/$b; done
o=/tmp/ab5; mkdir -p $o
one() { # bin case res steps end tag [extra...]
  local b=$1 c=$2 r=$3 n=$4 e=$5 tag=$6; shift 6
  local at=$o/${c}_$r.$b.$n.$tag
  timeout 100 .gpubin/$b run $c --resolution $r --backend gpu --precision f32 --max-steps $n --end-time $e --out /tmp/r --quiet --force "$@" > $at.stdout.txt 2>&1
  echo "exit $?" >> $at.stdout.txt
  cp /tmp/r/histories.csv $at.histories.csv 2>/dev/null
  rm -rf /tmp/r; echo "$at $(grep 'steps in' $at.stdout.txt)"
}
for rep in r1 r2; do for b in final loopfree; do
  one $b dam_break_3d gpu 50 0.11 $rep --set integrator=symplectic_pec
  one $b dam_break_3d gpu 350 0.11 $rep --set integrator=symplectic_pec
  one $b dam_break_2d 0.1mm 100 0.28 $rep
  one $b dam_break_2d 0.1mm 700 0.28 $rep
  one $b pysph_impact3d 0.25mm 40 1e-4 $rep
  one $b pysph_impact3d 0.25mm 440 1e-4 $rep
done; done
tar czf $OUT/ab5.tgz -C /tmp ab5
