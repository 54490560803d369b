#!/bin/sh
# dense_case.sh > dense.toml: cases/borvik_axisymmetric.toml written every 2.5 µs with ε̄_p, for
# ligament.py. Run from the repository's root; the copy names the stdlib model as the case does.
#     pairsum run dense.toml --resolution l333 --set thickness=8 --set v_impact=298 \
#         --set nonlocal_hardening=0 --set end_time="110 us" --out nl0_8_k12
sed -e 's/^interval = "50 us"/interval = "2.5 us"/' \
    -e 's/^fields = \["v", "p", "eps_p", "D"\]/fields = ["v", "p", "eps_p", "D", "eps_nl"]/' \
    cases/borvik_axisymmetric.toml
