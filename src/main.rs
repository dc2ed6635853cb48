//! The `dofray` command line.

#![deny(unsafe_code)]

mod cli;

use std::process::ExitCode;

use clap::Parser;
use dofray::scene::builtin;

use cli::args::{Cli, Command};
use cli::bench::run_bench;
use cli::render::{run_merge, run_render};
use cli::report::{report_error, version_text};

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind as Clap;
            return match e.kind() {
                Clap::DisplayVersion => {
                    print!("{}", version_text());
                    ExitCode::SUCCESS
                }
                // --help and friends print and exit 0; real errors exit 2 (clap's usage status).
                _ if !e.use_stderr() || !std::env::args().skip(1).any(|a| a == "--json") => {
                    e.exit()
                }
                _ => {
                    let _ = e.print();
                    let text = e.render().to_string();
                    let message = text
                        .lines()
                        .next()
                        .unwrap_or_default()
                        .trim_start_matches("error: ");
                    println!(
                        "{}",
                        dofray::exit::json_error(dofray::exit::ErrorKind::Usage, message)
                    );
                    ExitCode::from(dofray::exit::USAGE)
                }
            };
        }
    };
    let (result, json) = match &cli.command {
        Command::Render(a) => (run_render(a), a.json),
        Command::Bench(a) => (run_bench(a).map(|()| ExitCode::SUCCESS), a.json),
        Command::Merge(a) => (run_merge(a).map(|()| ExitCode::SUCCESS), a.json),
        Command::Scenes => {
            for (name, about) in builtin::BUILTIN {
                println!("{name:<10} {about}");
            }
            (Ok(ExitCode::SUCCESS), false)
        }
    };
    match result {
        Ok(code) => code,
        Err(e) => report_error(dofray::exit::classify(e.as_ref()), &format!("{e:#}"), json),
    }
}
