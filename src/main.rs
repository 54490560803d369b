fn main() {
    // Parsing and checking recurse over the syntax tree; a big stack keeps pathological nesting
    // (thousands of parentheses) an error message rather than a stack overflow.
    let worker = std::thread::Builder::new().stack_size(512 << 20).spawn(pairsum::cli::main);
    let code = match worker.map(|w| w.join()) {
        Ok(Ok(code)) => code,
        _ => 101,
    };
    std::process::exit(code);
}
