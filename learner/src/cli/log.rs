//! `learner log`: MCAP log tools (summary, integrity check, crash
//! recovery).

use anyhow::Result;
use clap::Subcommand;
use std::path::PathBuf;

/// `learner log`'s subcommands.
#[derive(Debug, Subcommand)]
pub enum LogCmd {
    /// Channels, message counts and time span of a complete log, and the
    /// gaps in its 1 kHz channels.
    Info {
        /// The log.
        file: PathBuf,
    },
    /// Reads every record and chunk; reports the first damage by byte offset
    /// (exit status 1), then the gaps in the 1 kHz channels.
    Check {
        /// The log.
        file: PathBuf,
    },
    /// Writes a valid copy of everything intact in a truncated or damaged
    /// log (the input is left as it is).
    Recover {
        /// The damaged log.
        file: PathBuf,
        /// Where the copy goes (default: FILE with `.recovered.mcap`).
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
}

/// Runs one `learner log` subcommand.
pub fn run(cmd: LogCmd) -> Result<()> {
    use learner_node::log;
    match cmd {
        LogCmd::Info { file } => {
            let r = log::LogReader::open(&file)?;
            println!("{}: {} bytes", file.display(), r.len_bytes());
            if let Some((a, b)) = r.time_span() {
                println!(
                    "log time {:.3} s to {:.3} s ({:.3} s)",
                    a as f64 * 1e-9,
                    b as f64 * 1e-9,
                    (b - a) as f64 * 1e-9
                );
            }
            println!(
                "{:<24} {:>9}  {:<28} encoding",
                "topic", "messages", "schema"
            );
            for t in r.topics() {
                println!(
                    "{:<24} {:>9}  {:<28} {}",
                    t.topic, t.messages, t.schema, t.encoding
                );
            }
            print_gaps(&r)
        }
        LogCmd::Check { file } => {
            let rep = log::scan(&file)?;
            println!(
                "{}: {} chunks, {} messages, {} bytes intact{}",
                file.display(),
                rep.chunks,
                rep.messages,
                rep.readable_bytes,
                if rep.complete { ", complete" } else { "" }
            );
            if let Some((offset, what)) = rep.problem {
                anyhow::bail!(
                    "{}: damaged at byte offset {offset}: {what}; `learner log recover {}` keeps \
                     everything before it",
                    file.display(),
                    file.display()
                );
            }
            print_gaps(&log::LogReader::open(&file)?)
        }
        LogCmd::Recover { file, output } => {
            let out = output.unwrap_or_else(|| file.with_extension("recovered.mcap"));
            let rep = log::recover(&file, &out)?;
            match &rep.damage {
                Some((offset, what)) => println!(
                    "{}: damage at byte offset {offset} ({what}); kept the {} bytes before it",
                    file.display(),
                    rep.readable_bytes
                ),
                None => println!("{}: no damage found", file.display()),
            }
            println!(
                "wrote {}: {} messages on {} channels",
                out.display(),
                rep.messages,
                rep.channels
            );
            if rep.channels_without_schema > 0 {
                println!(
                    "  {} channels lost their schema record; kept without a schema",
                    rep.channels_without_schema
                );
            }
            Ok(())
        }
    }
}

/// Prints the gaps of every 1 kHz channel of a log (lost messages are
/// reported, not an error: the file itself is intact).
fn print_gaps(r: &learner_node::log::LogReader) -> Result<()> {
    let gaps = learner_node::log::log_gaps(r)?;
    if gaps.is_empty() {
        println!("1 kHz channels: none");
    }
    for line in learner_node::log::gaps::describe(&gaps) {
        println!("1 kHz {line}");
    }
    Ok(())
}
