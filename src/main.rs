//! The `dreampolicy` CLI: one subcommand per pipeline stage (see `cli`).
use clap::Parser;

mod cli;

fn main() {
    let cli = cli::Cli::parse();
    if let Err(e) = cli::run(cli) {
        eprintln!("error: {}", error_chain(&e));
        std::process::exit(1);
    }
}

/// The error and its causes joined by `: ` (anyhow's `{:#}`), leaving out a
/// cause whose text the message already ends with: our typed errors print
/// their source (`path: No such file or directory`) and also expose it as the
/// source, which would otherwise be printed twice.
/// Each cause keeps its first line: libtorch's messages carry a C++ backtrace
/// after it, printed only with `RUST_BACKTRACE` set.
fn error_chain(e: &anyhow::Error) -> String {
    let mut out = String::new();
    let verbose = std::env::var_os("RUST_BACKTRACE").is_some_and(|v| v != "0");
    for cause in e.chain() {
        let full = cause.to_string();
        let text = if verbose {
            full.clone()
        } else {
            dreampolicy::checkpoint::first_line(&full).to_string()
        };
        if out.is_empty() {
            out = text;
        } else if !out.ends_with(&text) {
            out.push_str(": ");
            out.push_str(&text);
        }
    }
    out
}
