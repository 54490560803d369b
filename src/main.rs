fn main() {
    // Mesa's Vulkan driver complains on stderr when XDG_RUNTIME_DIR is unset (it is harmless);
    // set it before any thread starts.
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
    }
    // Parsing and checking recurse over the syntax tree; a big stack keeps pathological nesting
    // (thousands of parentheses) an error message rather than a stack overflow.
    let worker = std::thread::Builder::new().stack_size(512 << 20).spawn(pairsum::cli::main);
    let code = match worker.map(|w| w.join()) {
        Ok(Ok(code)) => code,
        _ => 101,
    };
    std::process::exit(code);
}
