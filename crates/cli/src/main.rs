//! `romosplat`: the command-line front end. Thin: argument parsing, progress
//! and output; the work is done by the library crates.

mod cmd;
mod ctx;
mod keyframes;
mod pipeline;
mod plan;
mod report;

use clap::Parser;
pub use ctx::Ctx;

/// romosplat: clean 3D Gaussian splats from casual videos with people walking through.
#[derive(Debug, Parser)]
#[command(name = "romosplat", version, about)]
struct Cli {
    /// Print one machine-readable JSON object on stdout (human output stays on stderr).
    #[arg(long, global = true)]
    json: bool,
    /// No human output on stderr.
    #[arg(long, short, global = true)]
    quiet: bool,
    #[command(subcommand)]
    command: cmd::Command,
}

fn main() {
    let cli = Cli::parse();
    let ctx = Ctx {
        json: cli.json,
        quiet: cli.quiet,
    };
    match cmd::dispatch(&cli.command, &ctx) {
        Ok(value) => {
            if ctx.json {
                println!(
                    "{}",
                    serde_json::to_string(&value).unwrap_or_else(|_| "{}".into())
                );
            }
        }
        Err(err) => {
            // One line: the chain of causes joined, no backtrace.
            let msg = err
                .chain()
                .map(|c| c.to_string())
                .collect::<Vec<_>>()
                .join(": ");
            if ctx.json {
                println!("{}", serde_json::json!({ "error": msg }));
            }
            eprintln!("error: {msg}");
            std::process::exit(1);
        }
    }
}
