//! The `chiaro` command: parses arguments and wires the facade to files.
//! Exit codes: 0 success, 1 bad input or failed render, 2 usage.

mod cli;
mod commands;
mod progress;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
    // The server runs until Ctrl-C ends it; renders stop cleanly instead.
    if matches!(
        args.command,
        cli::Command::Render(_) | cli::Command::Compare(_)
    ) {
        progress::handle_interrupt();
    }
    if let Some(limit) = args.memory_limit {
        chiaro::budget::MemoryBudget::set_process(limit);
    }
    let result = match args.command {
        cli::Command::Render(r) => commands::render(r),
        cli::Command::Info {
            scene,
            system,
            define,
        } => {
            if system {
                commands::info_system();
            }
            scene.map_or(Ok(()), |scene| commands::info(&scene, &define))
        }
        cli::Command::Serve {
            scene,
            port,
            host,
            camera,
        } => camera
            .choice()
            .map_err(anyhow::Error::from)
            .and_then(|camera| {
                chiaro_serve::serve(
                    &scene,
                    chiaro_serve::ServeOptions {
                        host,
                        port,
                        camera,
                        ..Default::default()
                    },
                )
                .map_err(anyhow::Error::from)
            }),
        cli::Command::Compare(c) => commands::compare(c),
        cli::Command::Export {
            scene,
            to,
            output,
            define,
        } => commands::export(&scene, to.as_deref(), &output, &define),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(_) if progress::interrupted() => {
            eprintln!("interrupted: nothing written");
            ExitCode::from(progress::INTERRUPTED_EXIT)
        }
        Err(e) => {
            eprintln!("error: {}", one_cause_each(&e));
            ExitCode::from(1)
        }
    }
}

/// The error and its causes joined by `: `, leaving out a cause whose text
/// the message already holds (an error that prints its source and also
/// returns it from `source()` would otherwise say it twice).
fn one_cause_each(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let part = cause.to_string();
        if text.contains(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}
