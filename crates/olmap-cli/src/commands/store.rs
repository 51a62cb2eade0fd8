//! `olmap store`: scan-store files (`team.store`, `*.olstore`) — what one holds, several
//! merged into one, the readable records of a damaged one recovered. The library does the
//! work ([`olmap::team::store_info`], [`olmap::team::merge_store_files`],
//! [`olmap::team::salvage_store_file`]); this prints its reports.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Subcommand};
use olmap::team::{merge_store_files, salvage_store_file, store_info, StoreDamage, StoreRobotInfo};

/// Arguments of `olmap store`.
#[derive(Args)]
pub struct StoreArgs {
    /// What to do.
    #[command(subcommand)]
    pub command: StoreCommand,
}

/// The `olmap store` subcommands.
#[derive(Subcommand)]
pub enum StoreCommand {
    /// What a store file holds: version, bytes, robots, records per robot, scan-number
    /// ranges and gaps, and any damage with its byte offsets (exit status 1 when damaged).
    Info(InfoArgs),
    /// Merge store files into one (set union; a record held by two must be identical).
    Merge(MergeArgs),
    /// Recover every readable record of a damaged store into a new one, and report what
    /// was recovered and what was lost (with byte offsets).
    Salvage(SalvageArgs),
}

/// Arguments of `olmap store info`.
#[derive(Args)]
pub struct InfoArgs {
    /// The store file.
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `olmap store merge`.
#[derive(Args)]
pub struct MergeArgs {
    /// The store files to merge.
    #[arg(required = true, num_args = 1..)]
    pub stores: Vec<PathBuf>,
    /// The merged store to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `olmap store salvage`.
#[derive(Args)]
pub struct SalvageArgs {
    /// The damaged store file.
    pub file: PathBuf,
    /// The store to write with the recovered records.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs `olmap store`.
pub fn run(a: &StoreArgs) -> anyhow::Result<ExitCode> {
    match &a.command {
        StoreCommand::Info(a) => info(a),
        StoreCommand::Merge(a) => merge(a),
        StoreCommand::Salvage(a) => salvage(a),
    }
}

fn robots_table(robots: &[StoreRobotInfo]) -> String {
    let mut out = format!(
        "  {:<16} {:>8} {:>13} {:>10}  gaps\n",
        "robot", "records", "scans", "points"
    );
    for r in robots {
        let gaps: Vec<String> = r
            .gaps
            .iter()
            .map(|[a, b]| {
                if a == b {
                    a.to_string()
                } else {
                    format!("{a}-{b}")
                }
            })
            .collect();
        out.push_str(&format!(
            "  {:<16} {:>8} {:>13} {:>10}  {}\n",
            format!("{} ({})", r.name, r.robot),
            r.records,
            format!("{}..={}", r.first_seq, r.last_seq),
            r.points,
            if gaps.is_empty() {
                "none".to_string()
            } else {
                gaps.join(", ")
            }
        ));
    }
    out
}

fn damage_lines(damage: &[StoreDamage]) -> String {
    damage
        .iter()
        .map(|d| {
            let record = d
                .record
                .map_or_else(String::new, |i| format!(", from record {i}"));
            format!(
                "  damaged: bytes {}..{} ({} bytes{record}; record markers in it: {}): {}\n",
                d.start,
                d.end,
                d.end - d.start,
                d.records_seen,
                d.reason
            )
        })
        .collect()
}

fn info(a: &InfoArgs) -> anyhow::Result<ExitCode> {
    let info = store_info(&a.file)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
    } else {
        print!(
            "{}: olmap scan store version {}, {} bytes, {} records of {} robots ({} named){}\n{}{}",
            info.path,
            info.version,
            info.bytes,
            info.records,
            info.robots.len(),
            info.names,
            if info.intact {
                String::new()
            } else {
                format!(", DAMAGED: {} records lost", info.records_lost)
            },
            robots_table(&info.robots),
            damage_lines(&info.damage)
        );
    }
    Ok(if info.intact {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

fn merge(a: &MergeArgs) -> anyhow::Result<ExitCode> {
    let r = merge_store_files(&a.stores, &a.output)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        for i in &r.inputs {
            println!("  {}: {} records, {} new", i.path, i.records, i.added);
        }
        print!("{}", robots_table(&r.robots));
        println!(
            "{} stores -> {} records -> {} ({} bytes)",
            r.inputs.len(),
            r.records,
            r.output,
            r.bytes
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn salvage(a: &SalvageArgs) -> anyhow::Result<ExitCode> {
    let r = salvage_store_file(&a.file, &a.output)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        let s = &r.salvage;
        let expected = s
            .records_expected
            .map_or_else(|| "an unknown number".to_string(), |n| n.to_string());
        println!(
            "{}: version {}, {} bytes; header {}; {} of {expected} records recovered, {} lost{}",
            r.input,
            s.version,
            s.bytes,
            if s.header_intact {
                "intact"
            } else {
                "damaged (robot names lost)"
            },
            s.records_recovered,
            s.records_lost,
            if s.verified {
                ""
            } else {
                " (unverified: a version-1 file has one checksum for the whole file)"
            }
        );
        print!("{}{}", damage_lines(&s.damage), robots_table(&r.robots));
        println!("written to {} ({} bytes)", r.output, r.output_bytes);
    }
    Ok(ExitCode::SUCCESS)
}
