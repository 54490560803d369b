fn main() {
    std::process::exit(pairsum::cli::main());
}
