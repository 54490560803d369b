//! The harness of the generated-input tests (`tests/fuzz.rs`): a seeded generator per input, each
//! input run in a child process (the test binary itself) that reports every input it starts, so
//! that a panic, a stack overflow, an abort on a failed allocation or a hang is pinned to the
//! input that caused it; the parent saves that input under `target/fuzz-failures/` and goes on
//! with the next one.
//!
//! Input `k` of a kind is made from its own generator seeded by (seed, kind, k), so any input can
//! be made again alone: `PAIRSUM_FUZZ_REPLAY=k` (with the same `PAIRSUM_FUZZ_SEED`) runs only it.

pub mod alloc;
pub mod cases;
pub mod checkpoint;
pub mod dsl;
pub mod nodes;
pub mod text;
pub mod toml_mut;

use pairsum::diag::{Diagnostic, Sources};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// xorshift64*: small, fast, deterministic.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// The generator of input `index` of `kind`.
    pub fn for_input(seed: u64, kind: &str, index: u64) -> Rng {
        let mut h = seed ^ 0xcbf2_9ce4_8422_2325;
        for b in kind.bytes().chain(index.to_le_bytes()) {
            h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
        let mut r = Rng::new(h);
        r.next();
        r
    }
    pub fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in `0..n` (n > 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    pub fn chance(&mut self, percent: usize) -> bool {
        self.below(100) < percent
    }
    pub fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
    pub fn word(&mut self, words: &[&'static str]) -> &'static str {
        words[self.below(words.len())]
    }
}

/// What one input did, as far as the harness is concerned (a panic is caught around it).
pub enum Outcome {
    /// Accepted; the label says how far it went (`checked`, `planned`, `stored`, …).
    Accepted(String),
    /// Refused with a proper diagnostic or error; the label says which (a code such as `C0002`,
    /// or the start of the message).
    Refused(String),
    /// A property the input broke: a diagnostic without a code or a location, a span outside its
    /// file, an engine changed by a refused checkpoint, …
    Bad(String),
}

/// One kind of input: how to make input `k`, and how to feed it to pairsum.
pub trait Kind {
    fn name(&self) -> &'static str;
    /// The file extension a saved failure gets.
    fn extension(&self) -> &'static str;
    /// Input `index` (the first ones are the seeds themselves, unchanged).
    fn generate(&mut self, index: u64, rng: &mut Rng) -> Vec<u8>;
    fn run(&mut self, input: &[u8]) -> Outcome;
}

/// Settings from the environment.
pub struct Settings {
    pub seed: u64,
    /// Each input's time limit: past it the input is a failure (a hang).
    pub timeout: Duration,
    /// Bytes one input may allocate beyond what was held before it (a failure past it).
    pub alloc_limit: u64,
}

impl Settings {
    pub fn from_env() -> Settings {
        let var = |k: &str| std::env::var(k).ok().and_then(|s| s.parse::<u64>().ok());
        Settings {
            seed: var("PAIRSUM_FUZZ_SEED").unwrap_or(0x5eed_5eed),
            timeout: Duration::from_millis(var("PAIRSUM_FUZZ_TIMEOUT_MS").unwrap_or(10_000)),
            alloc_limit: var("PAIRSUM_FUZZ_ALLOC_MB").unwrap_or(1024) << 20,
        }
    }
}

/// The totals of one kind's run.
#[derive(Clone, Debug, Default)]
pub struct Report {
    pub kind: String,
    pub inputs: u64,
    /// Inputs refused with a diagnostic (or an error) rather than accepted.
    pub refused: u64,
    pub wall: Duration,
    /// The slowest input, in ms, and its index.
    pub slowest: (f64, u64),
    /// The most one input allocated beyond what was held before it, in bytes.
    pub most_allocated: u64,
    /// How many inputs ended how (`accepted: stored`, `refused: C0002`, …).
    pub outcomes: std::collections::BTreeMap<String, u64>,
    pub failures: Vec<Failure>,
}

#[derive(Clone, Debug)]
pub struct Failure {
    pub index: u64,
    /// `panic`, `hang`, `crash` (the process died: stack overflow, abort), `alloc` or `bad`.
    pub what: String,
    pub message: String,
    /// Where the input was saved.
    pub saved: Option<PathBuf>,
}

/// The child's side: `PAIRSUM_FUZZ_CHILD="kind start count"` runs those inputs, printing
/// `FUZZ-AT k` before each and `FUZZ-…` lines for what it finds, then `FUZZ-DONE …`.
pub fn child_main(kinds: &mut [Box<dyn Kind>]) {
    let Ok(spec) = std::env::var("PAIRSUM_FUZZ_CHILD") else { return };
    let settings = Settings::from_env();
    let mut parts = spec.split_whitespace();
    let (Some(kind), Some(start), Some(count)) = (parts.next(), parts.next(), parts.next()) else {
        panic!("PAIRSUM_FUZZ_CHILD=\"kind start count\", found {spec:?}")
    };
    let (start, count): (u64, u64) = (start.parse().expect("start"), count.parse().expect("count"));
    let kind = kinds.iter_mut().find(|k| k.name() == kind).unwrap_or_else(|| panic!("no input kind `{kind}`"));
    let watch = Watchdog::start(settings.timeout);
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let mut refused = 0u64;
    let mut labels: std::collections::BTreeMap<String, u64> = Default::default();
    let mut slowest = (0.0f64, start);
    let mut most = 0u64;
    let mut out = std::io::stdout();
    for k in start..start + count {
        let _ = writeln!(out, "FUZZ-AT {k}");
        let mut rng = Rng::for_input(settings.seed, kind.name(), k);
        let input = kind.generate(k, &mut rng);
        let held = alloc::reset_peak();
        let t = Instant::now();
        watch.begin(k);
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| kind.run(&input)));
        watch.end();
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let grew = alloc::peak().saturating_sub(held);
        most = most.max(grew);
        if ms > slowest.0 {
            slowest = (ms, k);
        }
        match result {
            Ok(Outcome::Accepted(label)) => *labels.entry(format!("accepted: {label}")).or_default() += 1,
            Ok(Outcome::Refused(label)) => {
                refused += 1;
                *labels.entry(format!("refused: {label}")).or_default() += 1;
            }
            Ok(Outcome::Bad(msg)) => {
                let _ = writeln!(out, "FUZZ-BAD {k} {}", one_line(&msg));
            }
            Err(payload) => {
                let _ = writeln!(out, "FUZZ-PANIC {k} {}", one_line(&panic_message(payload.as_ref())));
            }
        }
        if grew > settings.alloc_limit {
            let _ = writeln!(out, "FUZZ-ALLOC {k} allocated {} MiB", grew >> 20);
        }
    }
    std::panic::set_hook(hook);
    let labels = serde_json::to_string(&labels).expect("json");
    let _ = writeln!(out, "FUZZ-DONE {count} {refused} {:.3} {} {most} {labels}", slowest.0, slowest.1);
    let _ = out.flush();
}

/// A thread that ends the process when an input runs past its time limit (the input's thread
/// cannot be stopped), after saying which input it was.
struct Watchdog {
    t0: Instant,
    /// When the current input started (ms since `t0`; `u64::MAX`: none running), and its index.
    started: Arc<AtomicU64>,
    current: Arc<AtomicU64>,
}

impl Watchdog {
    fn start(limit: Duration) -> Watchdog {
        let w = Watchdog {
            t0: Instant::now(),
            started: Arc::new(AtomicU64::new(u64::MAX)),
            current: Arc::new(AtomicU64::new(0)),
        };
        let (t0, started, current) = (w.t0, w.started.clone(), w.current.clone());
        std::thread::spawn(move || loop {
            std::thread::sleep(Duration::from_millis(20));
            let s = started.load(Ordering::SeqCst);
            let now = t0.elapsed().as_millis() as u64;
            if s != u64::MAX && now.saturating_sub(s) > limit.as_millis() as u64 {
                let mut out = std::io::stdout().lock();
                let _ = writeln!(out, "FUZZ-HANG {} {}", current.load(Ordering::SeqCst), now - s);
                let _ = out.flush();
                std::process::exit(3);
            }
        });
        w
    }

    fn begin(&self, k: u64) {
        self.current.store(k, Ordering::SeqCst);
        self.started.store(self.t0.elapsed().as_millis() as u64, Ordering::SeqCst);
    }

    fn end(&self) {
        self.started.store(u64::MAX, Ordering::SeqCst);
    }
}

fn one_line(s: &str) -> String {
    s.replace('\\', "\\\\").replace('\n', "\\n")
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        s.to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "(non-string panic payload)".to_string()
    }
}

/// The parent's side: runs inputs `0..count` of `kind` in child processes, `jobs` at a time, in
/// chunks; a child that dies or hangs is restarted after the input it was on.
pub fn run_kind(kind: &mut dyn Kind, count: u64, jobs: usize, test_name: &str) -> Report {
    let settings = Settings::from_env();
    let name = kind.name().to_string();
    let start = Instant::now();
    let mut report = Report { kind: name.clone(), ..Report::default() };
    if let Some(k) = std::env::var("PAIRSUM_FUZZ_REPLAY").ok().and_then(|s| s.parse::<u64>().ok()) {
        let r = run_chunk(&name, k, 1, test_name);
        absorb(&mut report, r);
    } else {
        // Chunks of a few thousand inputs, so that `jobs` children share the work.
        let chunk = (count / (4 * jobs as u64).max(1)).clamp(1, 20_000);
        let ranges: Vec<(u64, u64)> = (0..count).step_by(chunk as usize).map(|s| (s, chunk.min(count - s))).collect();
        let next = std::sync::Mutex::new(ranges.into_iter());
        let results = std::sync::Mutex::new(vec![]);
        std::thread::scope(|scope| {
            for _ in 0..jobs.max(1) {
                scope.spawn(|| loop {
                    let Some((s, n)) = next.lock().expect("lock").next() else { break };
                    let r = run_chunk(&name, s, n, test_name);
                    results.lock().expect("lock").push(r);
                });
            }
        });
        for r in results.into_inner().expect("lock") {
            absorb(&mut report, r);
        }
    }
    report.wall = start.elapsed();
    report.failures.sort_by_key(|f| f.index);
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-failures");
    for f in report.failures.iter_mut().take(50) {
        let mut rng = Rng::for_input(settings.seed, &name, f.index);
        let input = kind.generate(f.index, &mut rng);
        let _ = std::fs::create_dir_all(&dir);
        let path = dir.join(format!("{name}-{}-{}.{}", settings.seed, f.index, kind.extension()));
        if std::fs::write(&path, &input).is_ok() {
            f.saved = Some(path);
        }
    }
    report
}

fn absorb(report: &mut Report, r: Report) {
    report.inputs += r.inputs;
    report.refused += r.refused;
    if r.slowest.0 > report.slowest.0 {
        report.slowest = r.slowest;
    }
    report.most_allocated = report.most_allocated.max(r.most_allocated);
    for (k, n) in r.outcomes {
        *report.outcomes.entry(k).or_default() += n;
    }
    report.failures.extend(r.failures);
}

/// Runs inputs `start..start + count` of `kind` in children until all have run.
fn run_chunk(kind: &str, start: u64, count: u64, test_name: &str) -> Report {
    let mut report = Report::default();
    let end = start + count;
    let mut from = start;
    while from < end {
        let exe = std::env::current_exe().expect("the test binary");
        let mut child = Command::new(exe)
            .args([test_name, "--exact", "--nocapture", "--test-threads=1"])
            .env("PAIRSUM_FUZZ_CHILD", format!("{kind} {from} {}", end - from))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start a child");
        let stderr = child.stderr.take().expect("stderr");
        let err_reader = std::thread::spawn(move || {
            // Keep the last lines: what a dying process said.
            let mut tail: Vec<String> = vec![];
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                tail.push(line);
                if tail.len() > 20 {
                    tail.remove(0);
                }
            }
            tail
        });
        let mut at = None;
        let mut done = false;
        let mut hang = false;
        for line in BufReader::new(child.stdout.take().expect("stdout")).lines().map_while(Result::ok) {
            let mut w = line.splitn(3, ' ');
            let (tag, k, rest) = (w.next().unwrap_or(""), w.next().unwrap_or(""), w.next().unwrap_or(""));
            let k: u64 = k.parse().unwrap_or(0);
            let fail = |what: &str| Failure { index: k, what: what.into(), message: rest.to_string(), saved: None };
            match tag {
                "FUZZ-AT" => at = Some(k),
                "FUZZ-PANIC" => report.failures.push(fail("panic")),
                "FUZZ-BAD" => report.failures.push(fail("bad")),
                "FUZZ-ALLOC" => report.failures.push(fail("alloc")),
                "FUZZ-HANG" => {
                    report.failures.push(Failure {
                        index: k,
                        what: "hang".into(),
                        message: format!("still running after {rest} ms"),
                        saved: None,
                    });
                    hang = true;
                }
                "FUZZ-DONE" => {
                    let f: Vec<&str> = line.split_whitespace().collect();
                    report.inputs += f.get(1).and_then(|s| s.parse::<u64>().ok()).unwrap_or(0);
                    report.refused += f.get(2).and_then(|s| s.parse::<u64>().ok()).unwrap_or(0);
                    let ms = f.get(3).and_then(|s| s.parse::<f64>().ok()).unwrap_or(0.0);
                    let idx = f.get(4).and_then(|s| s.parse::<u64>().ok()).unwrap_or(0);
                    if ms > report.slowest.0 {
                        report.slowest = (ms, idx);
                    }
                    let most = f.get(5).and_then(|s| s.parse::<u64>().ok()).unwrap_or(0);
                    report.most_allocated = report.most_allocated.max(most);
                    let json = line.splitn(7, ' ').nth(6).unwrap_or("{}");
                    let labels: std::collections::BTreeMap<String, u64> =
                        serde_json::from_str(json).unwrap_or_default();
                    for (k, n) in labels {
                        *report.outcomes.entry(k).or_default() += n;
                    }
                    done = true;
                }
                _ => {}
            }
        }
        let status = child.wait().expect("wait for a child");
        let tail = err_reader.join().unwrap_or_default();
        if done && status.success() {
            break;
        }
        // The child died (or hung) on input `at`: count what ran before it and go on after it.
        let Some(k) = at else {
            panic!("a fuzz child for `{kind}` died before its first input: {status}\n{}", tail.join("\n"));
        };
        if !hang {
            let said: Vec<&String> = tail.iter().filter(|l| !l.trim().is_empty()).collect();
            let message = format!(
                "the process died ({status}): {}",
                said.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(" | ")
            );
            report.failures.push(Failure { index: k, what: "crash".into(), message, saved: None });
        }
        report.inputs += k + 1 - from;
        from = k + 1;
    }
    report
}

/// Prints a kind's report and fails the test when an input failed.
pub fn conclude(report: &Report) {
    println!(
        "fuzz {}: {} inputs ({} refused) in {:.1} s; slowest {:.1} ms (input {}); most allocated by one input {:.1} MiB; {} failures",
        report.kind,
        report.inputs,
        report.refused,
        report.wall.as_secs_f64(),
        report.slowest.0,
        report.slowest.1,
        report.most_allocated as f64 / (1u64 << 20) as f64,
        report.failures.len()
    );
    let mut outcomes: Vec<(&String, &u64)> = report.outcomes.iter().collect();
    outcomes.sort_by(|a, b| b.1.cmp(a.1).then(a.0.cmp(b.0)));
    let shown: Vec<String> = outcomes.iter().take(12).map(|(k, n)| format!("{k} {n}")).collect();
    println!("  outcomes: {}", shown.join("; "));
    for f in report.failures.iter().take(30) {
        let saved = f.saved.as_ref().map(|p| p.display().to_string()).unwrap_or_default();
        println!("  {} at input {}: {}\n    saved to {saved}", f.what, f.index, f.message);
    }
    assert!(
        report.failures.is_empty(),
        "{} of {} `{}` inputs failed; rerun one alone with PAIRSUM_FUZZ_REPLAY=<input> (saved under target/fuzz-failures/)",
        report.failures.len(),
        report.inputs,
        report.kind
    );
}

/// Checks what an error or warning must have: a code, and a primary location inside a file that
/// the source map holds (on character boundaries); and that rendering them works.
pub fn check_diagnostics(sources: &Sources, diags: &[Diagnostic]) -> Result<(), String> {
    for d in diags {
        if d.code.len() != 5 {
            return Err(format!("a diagnostic without a proper code: {:?} {}", d.code, d.message));
        }
        let Some((span, _)) = &d.primary else {
            return Err(format!("{}[{}] has no location: {}", sev(d), d.code, d.message));
        };
        for s in std::iter::once(span).chain(d.secondary.iter().map(|(s, _)| s)) {
            let text = sources.text(s.file);
            if sources.name(s.file) == "<unknown>" {
                return Err(format!(
                    "[{}] points into file {}, which is not in the source map: {}",
                    d.code, s.file, d.message
                ));
            }
            let (a, b) = (s.start as usize, s.end as usize);
            if a > b || b > text.len() || !text.is_char_boundary(a) || !text.is_char_boundary(b) {
                return Err(format!(
                    "[{}] has the span {a}..{b} in `{}` ({} bytes), not on its characters: {}",
                    d.code,
                    sources.name(s.file),
                    text.len(),
                    d.message
                ));
            }
        }
    }
    let _ = pairsum::diag::render(sources, diags);
    Ok(())
}

fn sev(d: &Diagnostic) -> &'static str {
    if d.is_error() {
        "error"
    } else {
        "warning"
    }
}

/// A message shortened to what does not depend on the input: up to its first number, quote,
/// colon or parenthesis (`expected a number, found` rather than the value found).
pub fn label(message: &str) -> String {
    let cut = message.find(|c: char| c.is_ascii_digit() || "`'\"(:[{".contains(c)).unwrap_or(message.len());
    let mut l = message[..cut].trim().trim_end_matches([',', '.', '=']).trim().to_string();
    if l.is_empty() {
        l = "(other)".into();
    }
    l.chars().take(60).collect()
}

/// The label of diagnostics that refused an input: the first error's code.
pub fn code_of(diags: &[Diagnostic]) -> String {
    diags.iter().find(|d| d.is_error()).map_or("(no error)".into(), |d| d.code.to_string())
}

/// How many inputs of a kind a run makes: the kind's default in the test suite, `n` with
/// `PAIRSUM_FUZZ_INPUTS=n`.
pub fn inputs(default: u64) -> u64 {
    std::env::var("PAIRSUM_FUZZ_INPUTS").ok().and_then(|s| s.parse().ok()).unwrap_or(default)
}
