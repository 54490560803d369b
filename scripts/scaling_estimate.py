#!/usr/bin/env python3
"""On paper: the parallel efficiency of a run split into domains over many nodes (issue 42).

A model, not a measurement. Each node runs one rank whose threads compute its own particles; per
step a rank computes, then sends its halo (no overlap of the two is assumed). The inputs are
pairsum's own figures, measured on one core of this project's machine, and the plan's halo bytes
(`pairsum plan CASE`); the assumptions are stated in the output. Usage:

    scripts/scaling_estimate.py            # the two cases of the issue at 8, 64 and 512 nodes
"""

import math

# Stated assumptions.
CORES_PER_NODE = 64
THREAD_EFFICIENCY = 0.9  # measured 0.93-0.95 from 1 to 2 threads on this machine
BANDWIDTH = 100e9 / 8  # 100 Gb/s per node, bytes per second
LATENCY = 2e-6  # seconds per message
SKIN = 0.1  # the halo's skin, a fraction of the cut-off (backend::domains)
# The share of a particle's step that its neighbour search takes, which a rank also spends on its
# halo's particles (29 % of a step in `perf` on impact3d before Verlet lists).
SEARCH_SHARE = 0.3


def halo_particles(n, dim, layers, thickness=None):
    """Particles within `layers` spacings outside a domain of n particles: a cube (3D), a square
    (2D), or a column through a plate `thickness` spacings thick (cut in its plane only)."""
    if thickness is not None:
        side = math.sqrt(n / thickness)
        return ((side + 2 * layers) ** 2 - side**2) * thickness
    side = n ** (1.0 / dim)
    return (side + 2 * layers) ** dim - n


def estimate(case):
    rows = []
    for nodes in (8, 64, 512):
        n = case["particles"] / nodes
        layers = case["reach_spacings"] * (1 + SKIN)
        halo = halo_particles(n, case["dim"], layers, case.get("thickness"))
        work = n + SEARCH_SHARE * halo
        compute = work * case["ns_per_particle_step"] * 1e-9 / (CORES_PER_NODE * THREAD_EFFICIENCY)
        # Kept halos: the plan's bytes each step; at a rebuild a copy of each halo particle (the
        # fields the passes read at j).
        bytes_step = halo * (case["halo_bytes"] + case["copy_bytes"] / case["steps_per_rebuild"])
        neighbours = 26 if case["dim"] == 3 and case.get("thickness") is None else 8
        messages = (case["exchanges"] + 2 / case["steps_per_rebuild"]) * neighbours
        comm = bytes_step / BANDWIDTH + messages * LATENCY
        ideal = n * case["ns_per_particle_step"] * 1e-9 / (CORES_PER_NODE * THREAD_EFFICIENCY)
        rows.append((nodes, n, halo / n, compute, comm, ideal / (compute + comm)))
    return rows


CASES = [
    {
        "name": "Børvik 12 mm plate, FTLR19's 1.6 M particles (3D, the plate 15 spacings thick)",
        "particles": 1.6e6,
        "dim": 3,
        "thickness": 15,
        # `borvik_perforation` at its CI resolution (2,064 particles), one thread, 18.4-19.1 ms a
        # step (docs/results/mpi_scaling/benchmark_output.txt).
        "ns_per_particle_step": 8900.0,
        "reach_spacings": 2 * 1.3,  # support 2, h = 1.3 dx
        "halo_bytes": 304,  # pairsum plan borvik_perforation: 4 exchanges a step
        # A halo copy: group, material, id and the fields read at j, 200-208 B (tests/domains.rs,
        # a_halo_copy_carries_only_the_fields_the_passes_read_at_j; a whole particle is 584-608 B).
        "copy_bytes": 208,
        "exchanges": 4,
        "steps_per_rebuild": 6,  # measured: 16 rebuilds in 100 steps on 2 ranks
    },
    {
        "name": "dam break, 100 M particles (2D)",
        "particles": 100e6,
        "dim": 2,
        # `dam_break_2d` at 0.7 mm (27,382 particles), one thread, 2 evaluations a step: 21.6-21.9
        # ms a step (docs/results/mpi_scaling/benchmark_output.txt).
        "ns_per_particle_step": 791.0,
        "reach_spacings": 2 * 1.5,
        "halo_bytes": 112,
        # A halo copy: group, material, id, x, v, m, rho, h, p_over_rho2, c (a whole particle: 152 B
        # and the saved state).
        "copy_bytes": 96,
        "exchanges": 2,
        "steps_per_rebuild": 25,  # measured: 4 in 100 steps, each after a reorder
    },
]


def main():
    print(
        f"assumed: {CORES_PER_NODE} cores a node at {THREAD_EFFICIENCY:.0%} thread efficiency, one rank a node, "
        f"{BANDWIDTH * 8 / 1e9:.0f} Gb/s and {LATENCY * 1e6:.0f} µs a message, no overlap of computing and sending, "
        f"a rank's search also walks its halo ({SEARCH_SHARE:.0%} of a particle's step), probes and measures reduced "
        "on each rank (as they are but the four measures that compare neighbours); efficiency: the compute of a "
        "rank's own particles over the whole step"
    )
    for case in CASES:
        print(f"\n{case['name']}")
        print("| nodes | particles a node | halo / own | compute a step | send a step | efficiency |")
        print("| --- | --- | --- | --- | --- | --- |")
        for nodes, n, share, compute, comm, eff in estimate(case):
            print(f"| {nodes} | {n:,.0f} | {share:.1%} | {compute * 1e3:.3f} ms | {comm * 1e3:.3f} ms | {eff:.1%} |")


if __name__ == "__main__":
    main()
