//! Front end: the pest grammar (`grammar/pairsum.pest`) and the parser that turns a source file into
//! an AST whose every node carries its span.

pub mod ast;
mod parse;

pub use parse::{parse_expr, parse_file};
