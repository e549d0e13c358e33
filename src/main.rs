//! The `arcnav` command-line tool.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;
use arcnav::Config;
use clap::{ArgAction, Parser, Subcommand};

/// Reactive cross-country navigation: range images → untraversable cells →
/// local map → arc votes → steering commands.
#[derive(Debug, Parser)]
#[command(name = "arcnav", version, about, long_about = None, propagate_version = true)]
struct Cli {
    /// More log output (-v debug, -vv trace).
    #[arg(short, long, action = ArgAction::Count, global = true)]
    verbose: u8,
    /// Less log output (-q warnings only, -qq errors only).
    #[arg(short, long, action = ArgAction::Count, global = true, conflicts_with = "verbose")]
    quiet: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Print the effective configuration (defaults merged with FILE) as TOML,
    /// or validate FILE with --check.
    Config {
        /// A TOML file holding the keys to change; every other key keeps its
        /// default (see config/default.toml).
        file: Option<PathBuf>,
        /// Only validate FILE: exit status 0 when valid, 1 with the reason when not.
        #[arg(long, requires = "file")]
        check: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    init_logging(cli.verbose, cli.quiet);
    match run(cli.command) {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}

fn init_logging(verbose: u8, quiet: u8) {
    let level = match (verbose, quiet) {
        (0, 0) => "info",
        (1, _) => "debug",
        (v, _) if v >= 2 => "trace",
        (_, 1) => "warn",
        _ => "error",
    };
    // RUST_LOG, when set, refines the level per module.
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .init();
}

fn run(command: Command) -> anyhow::Result<ExitCode> {
    match command {
        Command::Config { file, check } => {
            let config = Config::load_or_default(file.as_deref())?;
            if check {
                let file = file.context("--check needs a FILE")?;
                println!("{}: valid", file.display());
            } else {
                match &file {
                    Some(f) => println!(
                        "# effective configuration: defaults merged with {}",
                        f.display()
                    ),
                    None => println!("# effective configuration: the defaults"),
                }
                print!("{}", config.to_toml());
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}
