//! Faults lose nothing: a checkpoint with any byte changed is refused; a run killed with SIGKILL
//! and restarted from its last checkpoint reports what the uninterrupted run reports, bit for bit,
//! on the CPU and on the GPU; a disk that fills during a run stops it with an error naming the
//! file, keeps every earlier output and the last checkpoint intact; a folder that cannot be
//! written is a clear error.
//!
//! The full-disk test mounts a small tmpfs in a private mount namespace (`unshare -rm`, util-linux;
//! no root needed where user namespaces are allowed), so it touches nothing outside its process.

mod common;
use pairsum::backend::cpu::CpuBackend;
use pairsum::backend::Backend;
use pairsum::engine::{checkpoint, setup, Engine};
use pairsum::runner::prepare;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

fn case(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("cases").join(format!("{name}.toml"))
}

fn fresh_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pairsum-faults-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

fn pairsum() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pairsum"))
}

/// The bundled elastic wave with one more probe, the bar's mean velocity integrated in time
/// (`integrate = true`): its sum runs across every checkpoint, so a restart must carry it on.
fn wave_case() -> &'static Path {
    static CASE: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    CASE.get_or_init(|| {
        let dir = fresh_dir("wave-case");
        let text = std::fs::read_to_string(case("elastic_wave")).expect("case");
        let probe = "\n[[probes]]\nname = \"mean_displacement\"\nfield = \"v\"\ncomponent = \"x\"\nreduce = \"mean\"\n\
                     integrate = true\nunit = \"m\"\n";
        let path = dir.join("elastic_wave.toml");
        std::fs::write(&path, text + probe).expect("write the case");
        path
    })
}

/// The run of the elastic wave used throughout (`wave_case`): 1D, VTK every 0.2 ms, a checkpoint
/// every 50 steps. On the CPU it runs at 0.5 mm (2,006 particles, about 4,400 steps, seconds); on
/// lavapipe, whose every step costs milliseconds whatever the size, at the CI spacing to 0.6 ms.
fn wave_args(backend: &str, out: &Path) -> Vec<String> {
    let case = wave_case().display().to_string();
    let mut a: Vec<String> = ["run", &case, "--quiet", "--checkpoint-every", "50", "--backend", backend]
        .iter()
        .map(|s| s.to_string())
        .collect();
    if backend == "cpu" {
        a.extend(["--resolution".into(), "paper".into()]);
    } else {
        a.extend(["--end-time".into(), "6e-4".into()]);
    }
    a.extend(["--out".into(), out.display().to_string()]);
    a
}

fn run_to_end(args: &[String]) {
    let o = pairsum().args(args).output().expect("pairsum runs");
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
}

/// The results of a run's report: each quantity with the bits of its value.
fn results(out: &Path) -> Vec<(String, u64)> {
    let text = std::fs::read_to_string(out.join("report.json")).expect("report.json");
    let json: serde_json::Value = serde_json::from_str(&text).expect("json");
    let rows = json["results"].as_array().expect("results");
    assert!(!rows.is_empty(), "{} has no results", out.display());
    rows.iter()
        .map(|r| {
            let v = r["value"].as_f64().unwrap_or_else(|| panic!("result {r} has no finite value"));
            (r["quantity"].as_str().expect("quantity").to_string(), v.to_bits())
        })
        .collect()
}

/// Everything under `dir/vtk`, by name.
fn vtk_files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir.join("vtk"))
        .expect("vtk folder")
        .map(|e| e.expect("entry").path())
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&p).expect("read")))
        .collect();
    files.sort();
    files
}

fn bytes(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every file under `dir`.
fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = vec![];
    for e in std::fs::read_dir(dir).expect("folder") {
        let p = e.expect("entry").path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

/// Two text files are the same; otherwise fails at the first line that differs.
fn assert_same_text(a: &Path, b: &Path) {
    let (x, y) = (text(a), text(b));
    let (xs, ys): (Vec<&str>, Vec<&str>) = (x.lines().collect(), y.lines().collect());
    if let Some(k) = (0..xs.len().max(ys.len())).find(|k| xs.get(*k) != ys.get(*k)) {
        panic!(
            "{} and {} differ first at line {}: {:?} against {:?}",
            a.display(),
            b.display(),
            k + 1,
            xs.get(k),
            ys.get(k)
        );
    }
}

/// The step a checkpoint was written at (its JSON header's `step`).
fn checkpoint_step(path: &Path) -> u64 {
    let data = bytes(path);
    let nl = data.iter().position(|b| *b == b'\n').expect("header line");
    let header: serde_json::Value = serde_json::from_slice(&data[..nl]).expect("header");
    header["step"].as_u64().expect("step")
}

/// A run killed with SIGKILL as soon as it has written its second checkpoint, restarted from the
/// checkpoint it left, gives the uninterrupted run's results, histories and VTK files bit for bit.
fn killed_and_restarted_equals_uninterrupted(backend: &str) {
    let straight = fresh_dir(&format!("straight-{backend}"));
    run_to_end(&wave_args(backend, &straight));
    let steps =
        serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(straight.join("report.json")).unwrap())
            .unwrap()["steps"]
            .as_u64()
            .expect("steps");

    let killed = fresh_dir(&format!("killed-{backend}"));
    let mut child = pairsum().args(wave_args(backend, &killed)).spawn().expect("pairsum starts");
    let file = killed.join("checkpoint.bin");
    let started = Instant::now();
    while !(file.is_file() && checkpoint_step(&file) >= 100) {
        assert!(child.try_wait().expect("wait").is_none(), "the run ended before it could be killed: make it longer");
        assert!(started.elapsed() < Duration::from_secs(300), "no second checkpoint after 300 s");
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().expect("SIGKILL");
    let status = child.wait().expect("wait");
    assert_eq!(status.signal(), Some(9), "the run was not killed but ended: {status}");
    let at = checkpoint_step(&file);
    assert!(at >= 100 && at < steps, "checkpoint at step {at} of {steps}");
    // The killed run left its histories up to its last checkpoint, the straight run's first rows.
    let (left, whole) = (text(&killed.join("histories.csv")), text(&straight.join("histories.csv")));
    assert!(left.lines().count() as u64 >= at + 2, "histories.csv left by the killed run at step {at}:\n{left}");
    assert!(whole.starts_with(&left), "the killed run's histories.csv is not the start of the straight run's");

    let mut resume = wave_args(backend, &killed);
    resume.extend(["--restart".into(), file.display().to_string()]);
    run_to_end(&resume);

    assert_eq!(results(&killed), results(&straight), "{backend}: the results differ");
    assert_same_text(&killed.join("histories.csv"), &straight.join("histories.csv"));
    let (a, b) = (vtk_files(&killed), vtk_files(&straight));
    assert_eq!(a.iter().map(|f| &f.0).collect::<Vec<_>>(), b.iter().map(|f| &f.0).collect::<Vec<_>>());
    for ((name, x), (_, y)) in a.iter().zip(&b) {
        assert!(x == y, "{backend}: {name} differs from the uninterrupted run's");
    }
    let notes = std::fs::read_to_string(killed.join("report.json")).unwrap();
    assert!(notes.contains(&format!("restarted from the checkpoint at step {at}")), "the report does not say so");
    let _ = std::fs::remove_dir_all(&straight);
    let _ = std::fs::remove_dir_all(&killed);
}

fn text(path: &Path) -> String {
    String::from_utf8(bytes(path)).expect("text")
}

/// The times of a `histories.csv`, each with its row.
fn rows(csv: &str) -> Vec<(f64, &str)> {
    csv.lines().skip(1).map(|l| (l.split(',').next().unwrap().parse().expect("a time"), l)).collect()
}

/// A run that ends leaves a checkpoint, and `--restart` from it with a later `--end-time` goes on:
/// its histories begin at t = 0 with the first run's, and its result is the one of a run straight
/// to the later time (within the one step the first run shortened to land on its end time).
#[test]
fn a_finished_run_restarted_with_a_later_end_time_continues_its_histories_to_the_straight_runs_result() {
    let work = fresh_dir("extend");
    let args = |out: &Path, end: &str| -> Vec<String> {
        let case = wave_case().display().to_string();
        let a = ["run", &case, "--quiet", "--checkpoint-every", "1000", "--end-time", end, "--out"];
        a.iter().map(|s| s.to_string()).chain([out.display().to_string()]).collect()
    };
    let (first, straight) = (work.join("first"), work.join("straight"));
    run_to_end(&args(&first, "1.1e-3"));
    run_to_end(&args(&straight, "2.2e-3"));
    let first_csv = text(&first.join("histories.csv"));
    let mut resume = args(&first, "2.2e-3");
    resume.extend(["--restart".into(), first.join("checkpoint.bin").display().to_string()]);
    run_to_end(&resume);

    let (before, after, whole) =
        (rows(&first_csv), text(&first.join("histories.csv")), text(&straight.join("histories.csv")));
    let (after, whole) = (rows(&after), rows(&whole));
    assert_eq!(before.last().map(|r| r.0), Some(1.1e-3), "the first run ends at 1.1 ms");
    assert_eq!(&after[..before.len()], &before[..], "the extended histories do not begin with the first run's");
    assert_eq!(after.last().map(|r| r.0), Some(2.2e-3), "the extended histories do not reach 2.2 ms");
    // Up to the step the first run shortened, the straight run's rows are the same bits.
    assert_eq!(&after[..before.len() - 1], &whole[..before.len() - 1]);
    let speed = |out: &Path| f64::from_bits(results(out)[0].1);
    let (extended, straight_speed) = (speed(&first), speed(&straight));
    assert!(
        ((extended - straight_speed) / straight_speed).abs() < 1e-4,
        "wave speed {extended} after the extension, {straight_speed} straight"
    );
    let _ = std::fs::remove_dir_all(&work);
}

#[test]
fn a_run_killed_and_restarted_on_the_cpu_reports_the_uninterrupted_runs_figures_bit_for_bit() {
    killed_and_restarted_equals_uninterrupted("cpu");
}

#[test]
fn a_run_killed_and_restarted_on_the_gpu_reports_the_uninterrupted_runs_figures_bit_for_bit() {
    killed_and_restarted_equals_uninterrupted("gpu");
}

fn engine_for(name: &str) -> Engine<CpuBackend<f64>> {
    let (scene, plan) = prepare(&case(name), &Default::default()).unwrap_or_else(|e| panic!("{e}"));
    let store = setup::build_store::<f64>(&plan, &scene.particles, &scene.materials).expect("store");
    let mut e = Engine::new(CpuBackend::new(plan, store, scene.mirrors.clone()).expect("backend"), scene.config);
    e.initialise().expect("initialise");
    e
}

#[test]
fn a_checkpoint_with_any_one_byte_changed_or_cut_off_is_refused_and_restores_nothing() {
    let mut e = engine_for("elastic_wave");
    for _ in 0..20 {
        e.step().expect("step");
    }
    let good = checkpoint::encode(&e, b"the runner's record").expect("encode");
    let mut target = engine_for("elastic_wave");
    let before = target.backend.snapshot().expect("snapshot");
    let mut seed = 0x5eed_u64;
    let mut refused = 0;
    for k in 0..good.len() {
        let mut bad = good.clone();
        // A random non-zero change of byte k: one bit, or several.
        let flip = loop {
            let r = (common::rnd(&mut seed) * 256.0) as u8;
            if r != 0 {
                break r;
            }
        };
        bad[k] ^= flip;
        let err = checkpoint::decode(&mut target, &bad).expect_err("a changed byte must be refused");
        assert!(err.to_string().contains("corrupted"), "byte {k}: {err}");
        refused += 1;
    }
    for len in (0..good.len()).step_by(7) {
        checkpoint::decode(&mut target, &good[..len]).expect_err("a cut-off checkpoint must be refused");
    }
    let mut longer = good.clone();
    longer.push(0);
    checkpoint::decode(&mut target, &longer).expect_err("a byte added must be refused");
    // Nothing was restored by any of them.
    let after = target.backend.snapshot().expect("snapshot");
    assert!(after.columns == before.columns && after.id == before.id && target.step == 0);
    assert_eq!(refused, good.len());
    eprintln!(
        "{refused} one-byte changes and {} cut-offs of a {}-byte checkpoint refused",
        good.len().div_ceil(7),
        good.len()
    );
    // The checkpoint itself restores, with its record.
    let record = checkpoint::decode(&mut target, &good).expect("the good checkpoint restores");
    assert_eq!(record, b"the runner's record");
    assert_eq!((target.step, target.time.to_bits()), (e.step, e.time.to_bits()));
}

/// The elastic wave at its CI spacing on the CPU, a checkpoint every 50 steps, into `out`.
fn small_wave_args(out: &Path) -> Vec<String> {
    let mut a = wave_args("cpu", out);
    let at = a.iter().position(|s| s == "paper").expect("the resolution");
    a[at] = "ci".into();
    a
}

/// Runs pairsum with `args(out)`, its output folder `out` on a tmpfs of `kib` KiB mounted in a
/// private mount namespace; returns the exit code, stderr, and a copy of what the run left in
/// `out` (the tmpfs goes with the namespace).
fn run_on_a_small_disk(kib: u64, args: impl Fn(&Path) -> Vec<String>, work: &Path) -> (i32, String, PathBuf) {
    let mnt = work.join("mnt");
    let kept = work.join("kept");
    std::fs::create_dir_all(&mnt).unwrap();
    let script = r#"set -u
mount -t tmpfs -o size="$KIB"k pairsum-test "$MNT" || exit 90
"$@" > /dev/null 2> "$KEPT.stderr"
echo $? > "$KEPT.status"
cp -a "$MNT/out" "$KEPT"
"#;
    let o = Command::new("unshare")
        .args(["-rm", "sh", "-c", script, "sh"])
        .arg(env!("CARGO_BIN_EXE_pairsum"))
        .args(args(&mnt.join("out")))
        .env("KIB", kib.to_string())
        .env("KEPT", &kept)
        .env("MNT", &mnt)
        .output()
        .unwrap_or_else(|e| panic!("`unshare` (util-linux) is needed for the full-disk test: {e}"));
    assert!(
        o.status.success(),
        "could not mount a tmpfs in a private namespace (`unshare -rm`; user namespaces must be allowed): {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let status = std::fs::read_to_string(kept.with_extension("status")).expect("status").trim().parse().unwrap();
    let stderr = std::fs::read_to_string(kept.with_extension("stderr")).expect("stderr");
    (status, stderr, kept)
}

#[test]
fn a_disk_that_fills_during_a_run_stops_it_naming_the_file_and_keeps_earlier_outputs_and_the_last_checkpoint() {
    // The uninterrupted run, for its outputs and the sizes to fill a disk with.
    let work = fresh_dir("full-disk");
    let straight = work.join("straight");
    run_to_end(&small_wave_args(&straight));
    let kib_of = |n: usize| n.div_ceil(4096) as u64 * 4;
    let ckpt = bytes(&straight.join("checkpoint.bin")).len();
    let vtus: Vec<usize> = vtk_files(&straight).iter().filter(|f| f.0.ends_with(".vtu")).map(|f| f.1.len()).collect();
    assert!(vtus.len() > 6, "{} snapshots", vtus.len());
    // Room for the marker, the .pvd, three snapshots and one checkpoint with its temporary copy
    // (the first write): the disk fills a few snapshots or checkpoints into the run.
    let kib = 4 + 8 + vtus[..3].iter().map(|v| kib_of(*v)).sum::<u64>() + 2 * kib_of(ckpt);
    let (status, stderr, kept) = run_on_a_small_disk(kib, small_wave_args, &work);

    assert_eq!(status, 1, "a full disk is an error of the run; stderr: {stderr}");
    assert!(stderr.contains("No space left on device"), "{stderr}");
    assert!(stderr.contains("/out/"), "the error names no file: {stderr}");
    // No temporary file is left behind, and every snapshot the .pvd lists is the uninterrupted
    // run's, byte for byte.
    let left = vtk_files(&kept);
    let all: Vec<String> = walk(&kept).iter().map(|p| p.display().to_string()).collect();
    assert!(all.iter().all(|p| !p.ends_with(".tmp")), "a temporary file was left behind: {all:?}");
    let reference = vtk_files(&straight);
    let pvd = left.iter().find(|f| f.0.ends_with(".pvd")).expect("the .pvd");
    let pvd = String::from_utf8(pvd.1.clone()).expect("text");
    let listed: Vec<&str> = pvd.split("file=\"").skip(1).map(|s| &s[..s.find('"').unwrap()]).collect();
    assert!(listed.len() >= 3 && listed.len() < vtus.len(), "{} of {} snapshots kept", listed.len(), vtus.len());
    for name in &listed {
        let ours = left.iter().find(|f| f.0 == *name).unwrap_or_else(|| panic!("{name} is listed but missing"));
        let theirs = reference.iter().find(|f| f.0 == *name).expect("in the uninterrupted run");
        assert!(ours.1 == theirs.1, "{name} differs from the uninterrupted run's");
    }
    // The last checkpoint written is whole, and a restart from it finishes the run as if it had
    // never stopped.
    let file = kept.join("checkpoint.bin");
    assert!(checkpoint_step(&file) >= 50, "checkpoint at step {}", checkpoint_step(&file));
    let resumed = work.join("resumed");
    let mut args = small_wave_args(&resumed);
    args.extend(["--restart".into(), file.display().to_string()]);
    run_to_end(&args);
    assert_eq!(results(&resumed), results(&straight));
    assert_same_text(&resumed.join("histories.csv"), &straight.join("histories.csv"));
    let _ = std::fs::remove_dir_all(&work);
}

#[test]
fn an_output_folder_that_cannot_be_written_is_a_clear_error_naming_it() {
    let work = fresh_dir("unwritable");
    // A file where a folder is asked for: no user, root included, can write into it.
    let blocker = work.join("not-a-folder");
    std::fs::write(&blocker, "a user's file\n").unwrap();
    let out = blocker.join("out");
    let o = pairsum().args(wave_args("cpu", &out)).output().expect("pairsum runs");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains(&out.display().to_string()) || stderr.contains(&blocker.display().to_string()), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(std::fs::read_to_string(&blocker).unwrap(), "a user's file\n", "the user's file was changed");
    let _ = std::fs::remove_dir_all(&work);
}

/// A model whose `q` turns NaN (the log of −1 − q) at the particles with x > 25 mm from the step that
/// starts after t = 10.5 ms: step 11 at dt = 1 ms. WGSL leaves the log of a negative number to the
/// implementation; lavapipe, as IEEE 754, gives NaN.
const BLOWS_UP_MODEL: &str = "use kernels\ngroup metal\nkernel = wendland_c2\nstate q: scalar [-]\n\
     integrate { x' = v  q' = select(t > 0.0105 [s] && x.x > 0.025 [m], ln(-1 [-] - q) / 1 [s], 1 [1/s]) }\n";

/// `common::block_case` run with the blowing-up model, its `q` written out and probed.
fn blows_up_case() -> String {
    let top = "integrator = \"euler\"\nend_time = \"50 ms\"";
    let rest = "[output]\ninterval = \"2 ms\"\nfields = [\"q\"]\n\n[[probes]]\nname = \"q_max\"\nbody = \"block\"\n\
                field = \"q\"\nreduce = \"max\"\nunit = \"1\"\n\n[[results]]\nquantity = \"q_at_the_end\"\nprobe = \"q_max\"";
    common::block_case("blows_up.sph", top, "", rest)
}

/// A run whose field turns NaN stops on either backend with an error naming the step, the
/// particle, its group and the field, exits 1, and keeps the last good state as `last_good.vtu`
/// (every value finite) beside a report that says the run did not complete and gives no figures.
fn an_unstable_run_stops_naming_step_particle_and_field_and_keeps_the_last_good_state(backend: &str) {
    let dir = fresh_dir(&format!("unstable-{backend}"));
    std::fs::write(dir.join("blows_up.sph"), BLOWS_UP_MODEL).unwrap();
    std::fs::write(dir.join("blows_up.toml"), blows_up_case()).unwrap();
    let out = dir.join("out");
    let o = pairsum()
        .args(["run", "--quiet", "--backend", backend, "--out"])
        .arg(&out)
        .arg(dir.join("blows_up.toml"))
        .output()
        .expect("pairsum runs");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("went unstable at step 11 "), "{stderr}");
    assert!(stderr.contains("field `q` of particle ") && stderr.contains("(group metal) is not finite"), "{stderr}");
    let particle: usize =
        stderr.split("of particle ").nth(1).and_then(|s| s.split(' ').next()).unwrap().parse().unwrap();
    // The particles are filled row by row from the corner: 6 × 6 at 10 mm, x = 5 … 55 mm.
    assert!(particle % 6 >= 3, "particle {particle} lies at x < 25 mm and should not have failed");
    let kept = pairsum::report::vtk::read_vtu(&out.join("last_good.vtu")).expect("last_good.vtu");
    let q = &kept.fields.iter().find(|f| f.name == "q").expect("q kept").data;
    assert_eq!(q.len(), 36);
    // At the last good state, t = 10 ms: q = t / 1 s everywhere (from 0), finite.
    assert!(q.iter().all(|v| (v - 0.010).abs() < 1e-6), "{q:?}");
    // The report says so and gives no figure (the case's one result, a maximum of q, would be
    // one of the run so far).
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).expect("report.json")).unwrap();
    let notes = report["notes"].to_string();
    assert!(notes.contains("the run did not complete"), "{notes}");
    assert_eq!(report["results"].as_array().map(Vec::len), Some(0), "{}", report["results"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_unstable_run_on_the_cpu_stops_naming_step_particle_and_field_keeps_the_last_good_state_and_reports_no_figures() {
    an_unstable_run_stops_naming_step_particle_and_field_and_keeps_the_last_good_state("cpu");
}

#[test]
fn an_unstable_run_on_the_gpu_stops_naming_step_particle_and_field_keeps_the_last_good_state_and_reports_no_figures() {
    an_unstable_run_stops_naming_step_particle_and_field_and_keeps_the_last_good_state("gpu");
}

#[test]
fn a_restart_from_a_device_or_a_missing_file_is_a_clear_error() {
    let work = fresh_dir("restart-from");
    for (file, says) in [("/dev/zero", "not a regular file"), ("/nonexistent/checkpoint.bin", "No such file")] {
        let mut args = small_wave_args(&work.join("out"));
        args.extend(["--restart".into(), file.into()]);
        let o = pairsum().args(&args).output().expect("pairsum runs");
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{file}: {stderr}");
        assert!(stderr.contains(&format!("cannot restart from `{file}`: ")) && stderr.contains(says), "{stderr}");
    }
    let _ = std::fs::remove_dir_all(&work);
}

#[test]
fn a_reader_that_closes_the_pipe_ends_pairsum_cases_with_status_0_and_no_panic() {
    // The reader is gone before pairsum starts (`pairsum cases | head -0`), so its first write
    // meets a closed pipe whatever the timing.
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let out = pairsum().arg("cases").stdout(writer).output().expect("pairsum ends");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.code(), Some(0), "{stderr}");
}
