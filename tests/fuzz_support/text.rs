//! Mutations of any text: tokens (runs of word characters, runs of spaces, single other
//! characters) deleted, duplicated, swapped, replaced or spliced in from another file; characters
//! inserted and deleted; lines swapped, shuffled, deleted, duplicated or taken from another file.

use super::Rng;

/// Splits text into tokens that concatenate back to it: runs of word characters, runs of
/// whitespace, and single other characters.
pub fn tokenize(text: &str) -> Vec<&str> {
    #[derive(PartialEq, Clone, Copy)]
    enum Class {
        Word,
        Space,
        Other,
    }
    let class = |c: char| {
        if c.is_alphanumeric() || c == '_' {
            Class::Word
        } else if c.is_whitespace() {
            Class::Space
        } else {
            Class::Other
        }
    };
    let mut out = vec![];
    let mut start = 0;
    let mut prev: Option<Class> = None;
    for (k, c) in text.char_indices() {
        let cl = class(c);
        if let Some(p) = prev {
            if p != cl || cl == Class::Other {
                out.push(&text[start..k]);
                start = k;
            }
        }
        prev = Some(cl);
    }
    if start < text.len() {
        out.push(&text[start..]);
    }
    out
}

/// One random edit of a token list; `pool` holds tokens of the same file, `other` another seed,
/// `vocabulary` words of the input's language.
pub fn mutate_tokens(
    rng: &mut Rng,
    toks: &mut Vec<String>,
    pool: &[String],
    other: &[String],
    vocabulary: &[&'static str],
) {
    if toks.is_empty() {
        toks.push(rng.word(vocabulary).to_string());
        return;
    }
    let n = toks.len();
    let k = rng.below(n);
    match rng.below(7) {
        0 => {
            let len = 1 + rng.below(3.min(n - k));
            toks.drain(k..k + len);
        }
        1 => {
            let t = toks[k].clone();
            toks.insert(k, t);
        }
        2 => toks.swap(k, rng.below(n)),
        3 => toks[k] = rng.pick(pool).clone(),
        4 => toks[k] = rng.word(vocabulary).to_string(),
        5 => toks.insert(k, format!(" {} ", rng.word(vocabulary))),
        _ => {
            // Splice a run of another file's tokens.
            if !other.is_empty() {
                let a = rng.below(other.len());
                let b = (a + 1 + rng.below(40)).min(other.len());
                let piece: Vec<String> = other[a..b].to_vec();
                toks.splice(k..k, piece);
            }
        }
    }
}

/// Characters worth inserting anywhere: brackets, quotes, operators, line breaks, a NUL, a byte
/// order mark, characters of several bytes.
pub const CHARS: &[char] = &[
    '{', '}', '(', ')', '[', ']', '\'', '"', '/', '*', '^', '-', '\n', ' ', '0', 'é', '∇', '\u{0}', '#', '$', '=', ',',
    '.', '\t', '\r', '\u{feff}', '😀', '\\',
];

/// One random edit at the level of characters or lines; `other` is another file of the kind.
pub fn mutate_text(rng: &mut Rng, text: &mut String, other: &str) {
    let boundaries: Vec<usize> = text.char_indices().map(|(k, _)| k).chain([text.len()]).collect();
    let at = *rng.pick(&boundaries);
    match rng.below(8) {
        0 => text.insert(at, *rng.pick(CHARS)),
        1 => {
            if at < text.len() {
                text.remove(at);
            }
        }
        2 => {
            // Swap two lines.
            let mut lines: Vec<&str> = text.split('\n').collect();
            let (a, b) = (rng.below(lines.len()), rng.below(lines.len()));
            lines.swap(a, b);
            *text = lines.join("\n");
        }
        3 => {
            // Shuffle a run of lines.
            let mut lines: Vec<&str> = text.split('\n').collect();
            let a = rng.below(lines.len());
            let b = (a + 2 + rng.below(8)).min(lines.len());
            for k in (a + 1..b).rev() {
                let r = a + rng.below(k - a + 1);
                lines.swap(k, r);
            }
            *text = lines.join("\n");
        }
        4 => {
            // Delete a run of lines.
            let mut lines: Vec<&str> = text.split('\n').collect();
            let a = rng.below(lines.len());
            let b = (a + 1 + rng.below(4)).min(lines.len());
            lines.drain(a..b);
            *text = lines.join("\n");
        }
        5 => {
            // Duplicate a run of lines.
            let mut lines: Vec<&str> = text.split('\n').collect();
            let a = rng.below(lines.len());
            let b = (a + 1 + rng.below(6)).min(lines.len());
            let copy: Vec<&str> = lines[a..b].to_vec();
            let to = rng.below(lines.len() + 1);
            lines.splice(to..to, copy);
            *text = lines.join("\n");
        }
        6 => {
            // Lines of another file.
            let theirs: Vec<&str> = other.split('\n').collect();
            let a = rng.below(theirs.len());
            let b = (a + 1 + rng.below(5)).min(theirs.len());
            let mut lines: Vec<&str> = text.split('\n').collect();
            let to = rng.below(lines.len() + 1);
            lines.splice(to..to, theirs[a..b].iter().copied());
            *text = lines.join("\n");
        }
        _ => {
            // Cut the text short.
            text.truncate(at);
        }
    }
}

/// Replaces a random number in `text` (a run of digits, with sign, point and exponent) by `with`.
pub fn replace_number(rng: &mut Rng, text: &mut String, with: &str) -> bool {
    let b = text.as_bytes();
    let mut starts = vec![];
    let mut k = 0;
    while k < b.len() {
        if b[k].is_ascii_digit()
            && (k == 0 || !(b[k - 1].is_ascii_alphanumeric() || b[k - 1] == b'_' || b[k - 1] == b'.'))
        {
            let s = if k > 0 && b[k - 1] == b'-' { k - 1 } else { k };
            let mut e = k;
            while e < b.len() && (b[e].is_ascii_digit() || b[e] == b'.' || b[e] == b'_') {
                e += 1;
            }
            if e < b.len() && (b[e] == b'e' || b[e] == b'E') {
                let mut f = e + 1;
                if f < b.len() && (b[f] == b'-' || b[f] == b'+') {
                    f += 1;
                }
                if f < b.len() && b[f].is_ascii_digit() {
                    e = f;
                    while e < b.len() && b[e].is_ascii_digit() {
                        e += 1;
                    }
                }
            }
            starts.push((s, e));
            k = e;
        } else {
            k += 1;
        }
    }
    if starts.is_empty() {
        return false;
    }
    let (s, e) = *rng.pick(&starts);
    text.replace_range(s..e, with);
    true
}

/// Interesting numbers: zero and signs, the edges of integers and floats, non-finite values.
pub const NUMBERS: &[&str] = &[
    "0",
    "-0",
    "1",
    "-1",
    "2",
    "0.5",
    "-0.5",
    "1e-9",
    "1e-300",
    "1e-320",
    "5e-324",
    "1e6",
    "1e9",
    "1e300",
    "1e308",
    "1.8e308",
    "1e400",
    "-1e308",
    "nan",
    "inf",
    "-inf",
    "+inf",
    "NaN",
    "9007199254740993",
    "2147483647",
    "2147483648",
    "4294967296",
    "9223372036854775807",
    "9223372036854775808",
    "18446744073709551615",
    "18446744073709551616",
    "-9223372036854775808",
    "99999999999999999999999",
    "0.1",
    "3",
    "7",
    "1000",
    "0x10",
    "1_000",
    "0.0000001",
    "123456789",
];
