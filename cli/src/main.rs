//! The `fresco` command line: argument parsing, progress and exit codes; no algorithms.

fn main() {
    println!("fresco {}", env!("CARGO_PKG_VERSION"));
}
