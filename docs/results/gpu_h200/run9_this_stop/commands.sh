#!/usr/bin/env bash
# This stop's binary: the GPU against the CPU backend (16 cores) on one machine, benches/gpu/run.sh.
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
chmod +x .gpubin/pairsum
ONLY="sod_shock_tube_ci pysph_impact3d_0.5mm pysph_impact3d_0.25mm" benches/gpu/run.sh /tmp/o .gpubin/pairsum
ONLY="dam_break_2d_0.1mm dam_break_3d_gpu" SKIP_CPU=1 benches/gpu/run.sh /tmp/o2 .gpubin/pairsum
cp /tmp/o2/*.json /tmp/o2/*.csv /tmp/o2/*.txt /tmp/o/ 2>/dev/null
python3 benches/gpu/summarise.py /tmp/o > /tmp/o/summary.txt 2>&1; cat /tmp/o/summary.txt
tar czf $OUT/all.tgz -C /tmp/o .
