#!/bin/sh
# pull_case.sh > pull.toml: cases/borvik_axisymmetric.toml with two more probes, the power of the
# shaped plate's hourglass pull and of the contact on the bodies (Σ m v · a over the rings, every 5
# steps), for pull.py, which integrates them in time (stop 124). Run from the repository's root.
# Since stop 125 the case books the same work itself (the probes hourglass_work and contact_work,
# `integrate = true`); this script stays as the runs of stop 124 were made.
#     pairsum run pull.toml --resolution l333 --set thickness=8 --set v_impact=298 \
#         --set nonlocal_hardening=-3 --set hourglass_alpha=0 --out pwa0m3_8_k12
cat cases/borvik_axisymmetric.toml
cat <<'PROBES'

# stop 124: the power of the hourglass pull and of the contact on the bodies (host sums, every 5 steps)
[[probes]]
name = "hourglass_power"
expression = "m * dot(v, dv_hourglass)"
reduce = "sum"
unit = "W"
every = 5

[[probes]]
name = "contact_power"
expression = "m * dot(v, a_contact)"
reduce = "sum"
unit = "W"
every = 5
PROBES
