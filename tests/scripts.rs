//! The scripts in `scripts/` against the same figures computed here from the same files:
//! `scripts/shear_band.py` on the VTK series of a short Børvik run.

use pairsum::report::vtk::read_vtu;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The Børvik case at its CI resolution to 60 µs (VTK every 20 µs: the plug is sheared and some
/// particles have failed), into a fresh folder.
fn short_borvik_run(out: &Path) {
    let _ = std::fs::remove_dir_all(out);
    let o = Command::new(env!("CARGO_BIN_EXE_pairsum"))
        .args(["run", "borvik_perforation", "--backend", "cpu", "--quiet", "--end-time", "6e-5", "--out"])
        .arg(out)
        .output()
        .expect("pairsum runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// The script's table: per output time, its columns as numbers.
fn script_rows(out: &Path) -> Vec<Vec<f64>> {
    let o = Command::new("python3")
        .arg(root().join("scripts/shear_band.py"))
        .arg(out)
        .output()
        .unwrap_or_else(|e| panic!("python3 (which scripts/test.sh installs) is needed: {e}"));
    assert!(o.status.success(), "shear_band.py: {}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8(o.stdout).expect("text");
    text.lines()
        .skip(1)
        .map(|l| l.split('|').skip(1).map(|c| c.trim().parse().unwrap_or_else(|_| panic!("{l}"))).collect())
        .collect()
}

#[test]
fn shear_band_script_gives_the_strain_volume_and_failed_particles_computed_here_from_the_same_vtk() {
    let out = std::env::temp_dir().join(format!("pairsum-scripts-borvik-{}", std::process::id()));
    short_borvik_run(&out);
    let rows = script_rows(&out);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let dx_mm = 1000.0 * report["dx"].as_f64().expect("dx");
    // The snapshots after t = 0, in the order the .pvd lists them.
    let pvd = std::fs::read_to_string(out.join("vtk/borvik_perforation.pvd")).expect("pvd");
    let files: Vec<&str> = pvd.split("file=\"").skip(2).map(|s| &s[..s.find('"').unwrap()]).collect();
    assert_eq!(rows.len(), files.len(), "one row per snapshot after t = 0");
    assert!(rows.len() >= 3, "{} snapshots", rows.len());
    let mut failed_somewhere = false;
    for (row, file) in rows.iter().zip(&files) {
        let d = read_vtu(&out.join("vtk").join(file)).expect("vtu");
        let field = |name: &str| &d.fields.iter().find(|f| f.name == name).expect(name).data;
        let (body, eps_p, damage) = (field("body"), field("eps_p"), field("D"));
        // Σ V ε_p over the plate (body 1) within 20 mm of the axis, and the plate's failed
        // particles anywhere: columns 6 and 8 of the script's table (after run and time).
        let mut strain = 0.0;
        let mut failed = 0.0;
        for k in 0..body.len() {
            if body[k] != 1.0 {
                continue;
            }
            failed += if damage[k] >= 1.0 { 1.0 } else { 0.0 };
            let [x, y, _] = d.positions[k];
            if 1000.0 * x.hypot(y) <= 20.0 {
                strain += dx_mm.powi(3) * eps_p[k];
            }
        }
        assert!(strain.is_finite() && strain > 0.0, "{file}: Σ V ε_p = {strain}");
        // The script prints Σ V ε_p rounded to a whole mm³.
        assert!((row[4] - strain).abs() <= 0.5 + 1e-9 * strain, "{file}: script {} mm³, here {strain} mm³", row[4]);
        assert_eq!(row[6], failed, "{file}: failed particles");
        failed_somewhere |= failed > 0.0;
    }
    assert!(failed_somewhere, "no particle failed: the failed count is not tested");
    let _ = std::fs::remove_dir_all(&out);
}
