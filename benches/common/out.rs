//! The results directory of a program: its JSON (every figure, with the
//! host, the placement, and the steal and load over the run), a short
//! Markdown table (also printed), each run's files under `runs/`, and
//! points in the columns of `docs/cost.csv`.

use crate::common::args::Common;
use crate::common::host::{HostFacts, HostTimer};
use anyhow::{Context, Result};
use serde::Serialize;
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::{Instant, SystemTime, UNIX_EPOCH};

/// One point of a cost curve (`docs/cost.csv`): the cost `ns` of one frame
/// at `x` on `axis` (rate, depth, streams, payload), in `series`.
#[derive(Debug, Clone, Serialize)]
pub struct CostRow {
    pub axis: &'static str,
    pub x: f64,
    pub series: String,
    pub ns: f64,
}

/// A program's results directory, open for the length of the program.
pub struct Out {
    pub dir: PathBuf,
    program: &'static str,
    host: HostFacts,
    timer: HostTimer,
    t0: Instant,
    started_unix_s: u64,
}

impl Out {
    /// Creates the directory (`--out`, else `target/netfi-bench/<program>`)
    /// and starts the host's window over the whole program.
    pub fn create(common: &Common, program: &'static str) -> Result<Out> {
        let dir = common.out_dir(program);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let started_unix_s = SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
        Ok(Out { dir, program, host: HostFacts::read(), timer: HostTimer::now(), t0: Instant::now(), started_unix_s })
    }

    /// `runs/<name>/`, emptied.
    pub fn run_dir(&self, name: &str) -> Result<PathBuf> {
        let d = self.dir.join("runs").join(name);
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
        Ok(d)
    }

    /// The command that ran this program, as typed.
    pub fn command(&self) -> String {
        let args: Vec<String> = std::env::args().skip(1).filter(|a| a != "--bench").collect();
        let tail = if args.is_empty() { String::new() } else { format!(" -- {}", args.join(" ")) };
        format!("cargo bench --bench {}{tail}", self.program)
    }

    /// Writes `<program>.json` (`settings` and `figures` beside the host
    /// and its state over the program) and `<program>.md` (a line on the
    /// host, then `body`), and prints the Markdown.
    pub fn finish(&self, settings: &impl Serialize, figures: Value, body: &str) -> Result<()> {
        let over = self.timer.stop();
        let minutes = self.t0.elapsed().as_secs_f64() / 60.0;
        let doc = json!({
            "schema": format!("netfi-bench/{}/1", self.program),
            "command": self.command(),
            "started_unix_s": self.started_unix_s,
            "minutes": minutes,
            "host": self.host,
            "host_over_run": over,
            "settings": settings,
            "figures": figures,
        });
        let json_path = self.dir.join(format!("{}.json", self.program));
        std::fs::write(&json_path, serde_json::to_vec_pretty(&doc)?).with_context(|| format!("writing {}", json_path.display()))?;
        let mut md = format!("# netfi {}\n\n", self.program);
        let _ = writeln!(
            md,
            "`{}`: {}; {minutes:.1} minutes; over the run {}.\n\n{body}",
            self.command(),
            self.host.line(),
            over.line()
        );
        let md_path = self.dir.join(format!("{}.md", self.program));
        std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
        println!("\n{md}\nwritten: {} and {}", json_path.display(), md_path.display());
        Ok(())
    }

    /// Writes `cost.csv`: `rows` in the columns of `docs/cost.csv`, with
    /// this machine, the load and steal over the program so far, and the
    /// command, ready to be appended there.
    pub fn write_cost(&self, rows: &[CostRow]) -> Result<()> {
        let w = self.timer.stop();
        let machine = format!("{}-core {}", self.host.cores, self.host.cpu_model).replace(',', " ");
        let mut csv = String::from("axis,x,series,ns,machine,cores,load,steal,command\n");
        for r in rows {
            let _ = writeln!(
                csv,
                "{},{},{},{:.0},{machine},{},{:.1}-{:.1},{:.2},{}",
                r.axis,
                r.x,
                r.series.replace(',', ";"),
                r.ns,
                self.host.cores,
                w.load_start,
                w.load_end,
                w.steal_fraction * 100.0,
                self.command()
            );
        }
        let path = self.dir.join("cost.csv");
        std::fs::write(&path, csv).with_context(|| format!("writing {}", path.display()))
    }
}
