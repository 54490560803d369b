#!/usr/bin/env python3
"""Local hardening (`--set nonlocal_hardening=0`) on the 12 mm plate over the lattice (stop 122):
each level's residual speed averaged over five places of the projectile's edge (edge_phase -0.4 …
+0.4), as ../lattice_conserving/lattice.py does for the case. Runs: nh0_12_k<k> (phase 0, stop 121)
and nh0<phase>_12_k<k> (phase m04, m02, p02, p04). Run from anywhere:
    python3 docs/results/borvik_axisymmetric/edge_hardening/lattice.py"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "lattice_conserving"))
import lattice  # noqa: E402


def folder(plate, phase, k):
    return os.path.join(HERE, f"nh0{'' if phase == '0' else phase}_{plate}_k{k}")


if __name__ == "__main__":
    lattice.report(folder, plates=(12,))
