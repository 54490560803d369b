"""Where the axisymmetric Børvik runs make axial momentum (stop 118), from a run's particle profiles.
    python3 momentum_budget.py OUT [OUT ...]
OUT is a run of borvik_axisymmetric.toml with momentum_profiles.toml appended. At each profile's
time it prints each body's axial momentum (N s, each particle's ring: m 2 pi r v_y), the two
bodies' sum less the projectile's at impact (the momentum the scheme has made), and the axial
force (kN, sum of m 2 pi r a_y) of each term on each body: the body's own stresses (dv), which
cancel in a scheme whose pair forces are equal and opposite; the contact, whose two shares cancel
so; and the plate's hourglass pull. Forces are the last evaluation of the step the profile took.
"""
import csv
import sys

from release import load, ring_sum

TIMES = [10, 30, 50, 58, 62, 66]  # us, momentum_profiles.toml's


def impact_momentum(out):
    """The projectile's momentum at impact, 2 KE0 / v0, from the first row of the run's histories."""
    with open(f"{out}/histories.csv") as f:
        first = next(csv.DictReader(f))
    by_name = {k.split(" ")[0]: float(v) for k, v in first.items()}
    return 2 * by_name["kinetic_energy"] / abs(by_name["projectile_velocity"])


def budget(out):
    p0 = impact_momentum(out)
    print(f"{out}: the projectile's momentum at impact {p0:.3f} N s")
    print("  t (us)  projectile   plate    made | stresses: projectile   plate | contact: projectile   plate   sum | hourglass")
    for k, t in enumerate(TIMES):
        projectile = load(f"{out}/profiles/projectile_{k}.csv")
        plate = load(f"{out}/profiles/plate_{k}.csv")
        pj, pl = ring_sum(projectile, "v.y"), ring_sum(plate, "v.y")
        stresses = [ring_sum(projectile, "dv.y") / 1e3, ring_sum(plate, "dv.y") / 1e3]
        contact = [ring_sum(projectile, "a_contact.y") / 1e3, ring_sum(plate, "a_contact.y") / 1e3]
        hourglass = ring_sum(plate, "dv_hourglass.y") / 1e3
        print(f"  {t:6d}  {pj:10.3f}  {pl:6.3f}  {-(pj + pl) - p0:+6.3f} | {stresses[0]:19.2f} {stresses[1]:7.2f} | "
              f"{contact[0]:18.2f} {contact[1]:7.2f} {sum(contact):5.2f} | {hourglass:9.2f}")


if __name__ == "__main__":
    for out in sys.argv[1:]:
        budget(out)
