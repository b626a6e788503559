//! `bench site`: a site of N crane aisles under one rackd, fed a WMS's stream of stores,
//! retrieves in sequences to pick stations and jobs with deadlines (issue 52).
//!
//! TODO: module doc (figures, bounds arithmetic).

use std::sync::Arc;

use anyhow::ensure;
use rackd::wire::motion::Motion;

mod cpu;
mod figures;
mod offline;
mod report;
mod run;
mod wms;
mod workload;

use figures::Figures;
use run::Runtimes;
use workload::{Deadline, Workload};

/// `bench site`'s options.
#[derive(clap::Args, Debug, Clone)]
pub struct SiteArgs {
    /// Crane aisles; a list (`1,10,40`) runs each in turn.
    #[arg(long, value_delimiter = ',', default_value = "4")]
    pub aisles: Vec<u16>,
    /// Jobs per aisle (half retrieves, half stores).
    #[arg(long, default_value_t = 30)]
    pub jobs: usize,
    /// Jobs the WMS keeps open per aisle (over the site: this times the aisles).
    #[arg(long, default_value_t = 8)]
    pub backlog: usize,
    /// Share of each aisle's places full at the start.
    #[arg(long, default_value_t = 0.5)]
    pub fill: f64,
    /// Simulated seconds per real second.
    #[arg(long, default_value_t = 20.0)]
    pub time_scale: f64,
    /// Seed of the workload.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Bays of each aisle (1.4 m each).
    #[arg(long, default_value_t = 50)]
    pub bays: u16,
    /// Levels of each aisle (1.5 m each).
    #[arg(long, default_value_t = 12)]
    pub levels: u16,
    /// Pick stations (default: one per 10 aisles).
    #[arg(long)]
    pub stations: Option<usize>,
    /// Share of the retrieves that are members of a sequence.
    #[arg(long, default_value_t = 0.5)]
    pub sequenced: f64,
    /// Share of the other jobs that have a deadline.
    #[arg(long, default_value_t = 0.4)]
    pub deadlines: f64,
    /// Share of the deadlines that are tight.
    #[arg(long, default_value_t = 0.2)]
    pub tight: f64,
    /// A deadline with slack leaves this many times the crane's backlog time (backlog x
    /// the mean cycle) beside the job's own seconds.
    #[arg(long, default_value_t = 2.0)]
    pub slack: f64,
    /// rackd's crane poll period at the site's own pace, ms; rackd runs it divided by the
    /// time scale, as its heartbeat.
    #[arg(long, default_value_t = 200)]
    pub poll_ms: u64,
}

/// What the WMS posts beside the plain jobs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Nothing: the travel planner alone.
    Plain,
    /// The deadlines with slack, no tight one, no sequence.
    Slack,
    /// Every sequence and every deadline.
    Orders,
}

impl Mode {
    /// The three, in the order they run.
    const ALL: [Mode; 3] = [Mode::Plain, Mode::Slack, Mode::Orders];

    fn name(self) -> &'static str {
        match self {
            Mode::Plain => "travel only",
            Mode::Slack => "slack only",
            Mode::Orders => "orders",
        }
    }

    /// Whether a deadline is posted in this mode.
    fn posts(self, deadline: &Deadline) -> bool {
        match self {
            Mode::Plain => false,
            Mode::Slack => !deadline.tight,
            Mode::Orders => true,
        }
    }
}

/// Runs every aisle count of `--aisles` in every mode, and prints the figures and goals.
pub async fn run(args: SiteArgs) -> anyhow::Result<()> {
    ensure!((0.0..=1.0).contains(&args.fill), "--fill is a share, 0..=1");
    ensure!(args.backlog > 0 && args.time_scale > 0.0 && args.jobs > 1, "--backlog, --time-scale and --jobs must be above 0 (jobs above 1)");
    ensure!(!args.aisles.is_empty() && args.aisles.iter().all(|&n| n > 0), "--aisles: one count or more, each above 0");
    let fields = takes_fields();
    let motion = Motion::default();
    report::machine(&args, fields);
    let runtimes = Runtimes::new()?;
    let result = async {
        let mut all = Vec::new();
        for &aisles in &args.aisles {
            let workload = Arc::new(Workload::draw(&args, aisles, &motion));
            report::workload(&workload, &args);
            let mut runs = Vec::new();
            for mode in Mode::ALL {
                let run = run::one(&workload, mode, fields, &args, &runtimes).await?;
                let figures = Figures::of(&run, &workload, &motion);
                ensure!(
                    run.violations.is_empty() && run.refused == 0,
                    "{} aisles, {}: {} tasks refused, breaches: {:?}",
                    aisles,
                    mode.name(),
                    run.refused,
                    run.violations
                );
                report::row(&run, &figures, &workload);
                runs.push((run, figures));
            }
            report::compare(&runs, &workload, &args);
            all.push((workload, runs));
        }
        report::goals(&all, &args);
        Ok(())
    }
    .await;
    runtimes.stop();
    result
}

/// Whether rackd takes `sequence` and `deadline` on a job (issue 52's API), as its OpenAPI
/// document says; without them every mode posts plain jobs, and the figures are those of
/// the travel planner alone.
fn takes_fields() -> bool {
    let doc = serde_json::to_value(rackd::api::openapi()).unwrap_or_default();
    let properties = &doc["components"]["schemas"]["JobRequest"]["properties"];
    !properties["sequence"].is_null() && !properties["deadline"].is_null()
}
