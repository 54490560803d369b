//! Node files: CSV (`x,y,z[,volume]`) and LS-DYNA keyword decks (`*NODE`), from the seeds in
//! `fuzz/seeds/` and a few written here, mutated field by field (a column dropped, doubled or
//! replaced by an extreme number, a huge id, NaN, text; fixed-width columns shifted), line by line
//! (keywords replaced or inserted, lines deleted, doubled, spliced from another file) and character
//! by character; each read by `read_csv_nodes` or `read_lsdyna_nodes`, and a list that reads
//! turned into particles in 1, 2 and 3 dimensions. An error must name a line and a column that
//! lie in the file.

use super::text::{mutate_text, NUMBERS};
use super::{label, Kind, Outcome, Rng};
use pairsum::scene::geometry::{read_csv_nodes, read_lsdyna_nodes, NodeError};
use std::path::Path;

/// A deck with every layout and number form the reader knows (as `tests/geometry.rs` has it).
const DECK: &str = "$ a comment
*KEYWORD
*NODE
       1             0.0             0.0             0.0       0       0
       2          1.0E-3        -2.5e+00            1.50
$ a comment inside the section
       3            1.-3           2.5+1              -4
*ELEMENT_SOLID
       1       1       1       2       3       3       3       3       3       3
*NODE_RIGID_SURFACE
       9             9.0             9.0             9.0
*NODE
4, 1.0, 2.0, 3.0
5,-1.5D-2,0,7, 0, 0
*NODE %
1234567890             1.0             2.0             3.0
*END
";

const CSV: &str = "x,y,z,volume\n0,0,0,1\n1.5,2,3e-2,0.5\n\u{feff}-1,-2,-3,0.25 # a trailing comment\n";

/// Fields worth putting anywhere in a node line.
const FIELDS: &[&str] = &[
    "",
    " ",
    "abc",
    "x",
    "1.0D+400",
    "1D-3",
    "1.-3",
    "2.5+2",
    "1e",
    "--1",
    ".",
    "+",
    "-",
    "e5",
    "1,5",
    "1 5",
    "99999999999999999999",
    "-99999999999999999999",
    "2147483648",
    "1e-320",
    "0x1F",
    "1_000",
    "NaN",
    "nan",
    "inf",
    "-inf",
    "1e999",
    "-1e999",
    "\t1\t",
    "é",
    "1.0e+0000000000000000000001",
    "00000000000000000000000001",
];

const KEYWORDS: &[&str] = &[
    "*NODE",
    "*NODE %",
    "*NODE +",
    "*NODE -",
    "*node",
    "*KEYWORD",
    "*KEYWORD LONG=Y",
    "*KEYWORD LONG=S",
    "*KEYWORD  long = y",
    "*NODE_SET",
    "*INCLUDE",
    "*END",
    "*",
    "$",
    "$ *NODE",
    "*NODE%",
    "*NODE+",
    "  *NODE",
];

fn seeds(ext: &str) -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds");
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .map(|d| d.flatten().map(|e| e.path()).filter(|p| p.extension().is_some_and(|e| e == ext)).collect())
        .unwrap_or_default();
    files.sort();
    let mut out: Vec<String> = files.iter().filter_map(|p| std::fs::read_to_string(p).ok()).collect();
    out.push(if ext == "csv" { CSV.to_string() } else { DECK.to_string() });
    out
}

/// One edit of a data line's fields (comma-separated, or fixed-width columns).
fn mutate_fields(rng: &mut Rng, text: &mut String, csv: bool) {
    let lines: Vec<&str> = text.split('\n').collect();
    let data: Vec<usize> = (0..lines.len())
        .filter(|k| {
            let l = lines[*k].trim_start();
            !l.is_empty() && !l.starts_with(['*', '$', '#'])
        })
        .collect();
    if data.is_empty() {
        return;
    }
    let k = *rng.pick(&data);
    let line = lines[k];
    let new = if line.contains(',') || csv {
        let mut f: Vec<String> = line.split(',').map(str::to_string).collect();
        let i = rng.below(f.len());
        match rng.below(6) {
            0 if f.len() > 1 => {
                f.remove(i);
            }
            1 => {
                let x = f[i].clone();
                f.insert(i, x);
            }
            2 => f[i] = rng.word(NUMBERS).to_string(),
            3 => f[i] = rng.word(FIELDS).to_string(),
            4 => f.push(rng.word(NUMBERS).to_string()),
            _ => f.truncate(1 + rng.below(f.len())),
        }
        f.join(",")
    } else {
        // Fixed width: replace a column's text, keeping or breaking its width; or shift the rest.
        let chars: Vec<char> = line.chars().collect();
        let widths: &[usize] = if rng.chance(50) { &[8, 16, 16, 16, 8, 8] } else { &[20; 6] };
        let col = rng.below(widths.len());
        let start: usize = widths[..col].iter().sum::<usize>().min(chars.len());
        let end = (start + widths[col]).min(chars.len());
        let field = if rng.chance(50) { rng.word(NUMBERS) } else { rng.word(FIELDS) };
        let mut out: String = chars[..start].iter().collect();
        match rng.below(3) {
            0 => out.push_str(&format!("{field:>w$}", w = widths[col])),
            1 => out.push_str(field),
            _ => out.push_str(&" ".repeat(1 + rng.below(3))),
        }
        if rng.chance(80) {
            out.extend(&chars[end..]);
        }
        out
    };
    let mut lines: Vec<String> = lines.iter().map(|l| l.to_string()).collect();
    lines[k] = new;
    *text = lines.join("\n");
}

/// A keyword line replaced or inserted.
fn mutate_keywords(rng: &mut Rng, text: &mut String) {
    let mut lines: Vec<String> = text.split('\n').map(str::to_string).collect();
    let at = rng.below(lines.len() + 1);
    let kw = rng.word(KEYWORDS).to_string();
    if at < lines.len() && lines[at].trim_start().starts_with('*') && rng.chance(60) {
        lines[at] = kw;
    } else {
        lines.insert(at, kw);
    }
    *text = lines.join("\n");
}

/// Node files of one format.
pub struct NodeFiles {
    csv: bool,
    seeds: Vec<String>,
}

impl NodeFiles {
    pub fn csv() -> NodeFiles {
        NodeFiles { csv: true, seeds: seeds("csv") }
    }
    pub fn lsdyna() -> NodeFiles {
        NodeFiles { csv: false, seeds: seeds("k") }
    }
}

impl Kind for NodeFiles {
    fn name(&self) -> &'static str {
        if self.csv {
            "nodes_csv"
        } else {
            "nodes_lsdyna"
        }
    }
    fn extension(&self) -> &'static str {
        if self.csv {
            "csv"
        } else {
            "k"
        }
    }
    fn generate(&mut self, index: u64, rng: &mut Rng) -> Vec<u8> {
        if let Some(s) = self.seeds.get(index as usize) {
            return s.clone().into_bytes();
        }
        let mut text = rng.pick(&self.seeds).clone();
        let other = rng.pick(&self.seeds).clone();
        for _ in 0..1 + rng.below(4) {
            match rng.below(10) {
                0..=3 => mutate_fields(rng, &mut text, self.csv),
                4 if !self.csv => mutate_keywords(rng, &mut text),
                5 => {
                    // Many more lines than the seed (a count the reader did not expect).
                    let lines: Vec<&str> = text.split('\n').collect();
                    let k = rng.below(lines.len());
                    let copies = 1 + rng.below(200);
                    let mut out: Vec<&str> = lines[..k].to_vec();
                    out.extend(std::iter::repeat_n(lines[k], copies));
                    out.extend(&lines[k..]);
                    text = out.join("\n");
                }
                6 => {
                    // Line endings and separators of other systems.
                    text = match rng.below(3) {
                        0 => text.replace('\n', "\r\n"),
                        1 => text.replace(',', ";"),
                        _ => text.replace(' ', "\t"),
                    };
                }
                _ => mutate_text(rng, &mut text, &other),
            }
        }
        text.into_bytes()
    }
    fn run(&mut self, input: &[u8]) -> Outcome {
        let text = String::from_utf8_lossy(input);
        let name = if self.csv { "fuzz.csv" } else { "fuzz.k" };
        let read = if self.csv { read_csv_nodes(&text, name) } else { read_lsdyna_nodes(&text, name) };
        match read {
            Ok(nodes) => {
                for dim in 1..=3 {
                    let _ = nodes.to_particles(dim);
                }
                Outcome::Accepted("read".into())
            }
            Err(e) => match located(&text, &e) {
                Ok(()) => Outcome::Refused(label(&e.message)),
                Err(msg) => Outcome::Bad(msg),
            },
        }
    }
}

/// A node error's line and column lie in the text (the column may be one past a line's end).
fn located(text: &str, e: &NodeError) -> Result<(), String> {
    let lines: Vec<&str> = text.lines().collect();
    let n = lines.len().max(1);
    if e.line == 0 || e.line > n {
        return Err(format!("line {} of a file of {n} lines: {e}", e.line));
    }
    let len = lines.get(e.line - 1).map_or(0, |l| l.chars().count());
    if e.column == 0 || e.column > len + 1 {
        return Err(format!("column {} of a line of {len} characters: {e}", e.column));
    }
    if e.message.is_empty() {
        return Err(format!("no message: {e}"));
    }
    Ok(())
}
