//! `bench site`: a site of N crane aisles under one rackd, fed a WMS's stream of stores,
//! retrieves in sequences to pick stations and jobs with deadlines (issue 52), in
//! accelerated time.
//!
//! For each aisle count of `--aisles` (`1,10,40` runs three sites in turn) one workload is
//! drawn from `--seed` (`site/workload.rs`): N single-deep aisles of 2 rows x `--bays` x
//! `--levels`, `--fill` full; `--jobs` jobs per aisle, half retrieves of the stock, half
//! stores to empty places; a `--sequenced` share of the retrieves cut into sequences of 2
//! to 6 members (the last up to 7), each to one station; deadlines on a `--deadlines` share
//! of the other jobs, a `--tight` share of them tight. It runs three times, each against N
//! fresh crane simulators (the motion model, `--time-scale` times faster than the wall
//! clock) and a fresh rackd served in this process (one crane device per aisle, the
//! stations in `[[site.stations]]`, SQLite in a temporary folder):
//! - **travel only**: plain jobs, as before issue 52: the travel planner alone;
//! - **slack only**: the deadlines with slack posted, nothing else;
//! - **orders**: every sequence and every deadline posted.
//!
//! The WMS (`site/wms.rs`) posts in the same order each time, a sequence in one batch,
//! keeps `--backlog` jobs per aisle open over the site, and follows the ends on rackd's
//! live events.
//!
//! **Time.** The cranes run `--time-scale` times faster than the wall clock, and rackd runs
//! on the wall clock. So that rackd sees the site as it would at the site's own pace, each
//! of its times is divided by the scale too: the crane poll (`--poll-ms` at the site's pace,
//! 200, the crane's default) and heartbeat (500 ms); the motion model it plans with (the
//! simulator's, every time divided by the scale, so its estimates are wall-clock seconds)
//! and the margin it keeps before a deadline (`deadline_margin_s`, 30; whole seconds, so 2 at
//! x20, 40 s simulated); the transit times of `[[site.stations]]`; a deadline, which is the
//! post's wall-clock time plus its allowance divided by the scale. What does not shrink:
//! the disk's sync of each commit, the round trips to the cranes and the scheduler's delays
//! on a loaded machine, all multiplied by the scale in simulated time. The run is harder on
//! rackd's latency than the site itself would be.
//!
//! Figures (simulated time unless said otherwise):
//! - **jobs/h**: for each crane, its jobs over the time from the first post to its last
//!   completion, summed over the cranes. **bound**: that against the machines' own bound,
//!   the sum over the cranes of 3600 s / the least crane seconds per job that any order of
//!   the crane's share could take (`crane/bound.rs`: each job's forks and loaded run, and the
//!   least empty travel of an optimal assignment of job ends to job starts, knowing every
//!   job in advance). The ratio is the product of two shares: the crane's busy time over
//!   its span (below) and the bound's seconds per job over those the crane spent (the
//!   planner, which sees only the backlog, against perfect foresight);
//! - **busy/handov(er)**: of the cranes' time to their last completion, the share they
//!   moved (the simulators' busy seconds) and the share lost between a job becoming due and
//!   the crane taking it (the dispatch latency, below, summed). The rest they waited for
//!   work: nothing posted yet for the aisle, or only sequence members held back;
//! - **empty m**: metres travelled with an empty platform, over the site (the simulators'
//!   counters), printed after the table as each run's ratio to travel only, beside the
//!   share of stores a retrieve followed (dual cycles: from the put straight to the next
//!   pick, rather than back to the station empty);
//! - **inversions**: a retrieve of a sequence reaches its station at its crane's
//!   completion plus its aisle's transit (`workload.rs`: 15 s, plus the distance along the
//!   front, aisles 3.5 m apart, at 0.5 m/s). An inversion is a pair of members of one
//!   sequence where the higher position arrives first, counted within an aisle (both from
//!   one aisle) and across aisles, and by station;
//! - **late (t/s)**: the deadlines missed, tight and with slack, of those the workload gives
//!   (the same jobs in every run, posted or not): a job is late when its crane completes it
//!   after its deadline. After the table: how late they ended (median and most), and the
//!   offline schedule's (`site/offline.rs`), which knows every job's post and deadline in
//!   advance: its misses, a lower bound on any schedule's, and the jobs rackd missed that
//!   it meets;
//! - **latency**: the dispatch latency, in wall-clock milliseconds (p50/p99), from the
//!   moment a job could have gone to its crane (posted, the crane done with the task
//!   before, and in a run with sequences the member before it delivered and the transit
//!   difference passed) to the crane taking it (hand-over step 2, in the simulator's
//!   timeline); after the table in simulated seconds and as a share of the mean job;
//! - **rackd**: its CPU (`site/cpu.rs`: the process's minus the simulators' and the WMS's
//!   threads) over the run's wall time, as a share of one core; **ms/job** that per job
//!   completed. After the table: with the cranes online and idle (the 2 s before the first
//!   post), and at the site's own pace: the share divided by the scale, since each of
//!   rackd's periods and jobs comes that many times as often.
//!
//! **Bounds, worked out first** (2 shared cores, release build; the costs from a first run
//! at 1, 10 and 40 aisles of 6 jobs each, load average 12):
//! - *Can 40 simulators and rackd run on 2 cores, and at which scale?* A simulator ticks
//!   every 20 ms / scale, at least every 1 ms, idle or not: 1000 ticks a second at x20 and
//!   above; 40 idle simulators took 6% of a core (1.5 µs a tick). rackd polls each crane
//!   every `--poll-ms` / scale and writes its heartbeat every 500 ms / scale: at x20, 100
//!   reads and 40 writes a second per crane; idle, 1.0% of a core plus 0.12% per crane
//!   (9 µs a request): 5.8% at 40. At work, 40 cranes end 40 x 20 / 34 s = 24 jobs a wall
//!   second at x20, and rackd spent 17 ms of CPU per job beyond its idle share. Most of it
//!   is the cranes' status: each poll of a moving crane shows a new position, which is a
//!   `device.updated` event and a commit (123 such events per job in a 2-aisle run, against
//!   7 `job.updated`). So 5.8% + 24 x 1.7% = 47% of a core for rackd, 7% for the
//!   simulators, and the WMS's little: half a core of two, room left for a loaded machine.
//!   At x100, rackd's share would be five times that, more than both cores: x20 it is, which
//!   also keeps a run of 30 jobs an aisle near a minute of wall time.
//! - *Which scale keeps rackd's hand-over latency under 5% of a job?* A crane waits for
//!   rackd from its completion to its next task: the poll that sees the completion (half a
//!   poll on average), the commit of the outcome (its sync), the acknowledgement and the
//!   poll that sees it cleared (one poll), the planner and the four-step hand-over (five
//!   round trips): 1.5 polls and some 5 ms. A job takes 34 to 35 s here; 5% of it is 1.7 s.
//!   At the site's pace (200 ms polls): 0.3 s + 5 ms, 0.9%. At x20 the polls shrink with
//!   the scale but the 5 ms, and any delay of the scheduler, grow twentyfold: 0.3 s + 0.1 s,
//!   1.2%. It reaches 5% at 85 ms of wall time; at x40 at 43 ms; at x100 at 17 ms, less
//!   than the first run's p50 of 25 to 40 ms (its p99 was hundreds of ms, at load 12).
//! - *Throughput >= 95% of the machines' bound at 40 aisles* lies beyond the bound on
//!   this workload, whatever rackd's latency: the ratio is the busy share times the
//!   planner's share of perfect foresight, and hand-overs take 1.2 to 1.5% of a crane's
//!   time at x20 (0.9% at the site's pace), so the goal needs the planner at 96.5% of
//!   foresight or more. The travel planner reaches 94 to 96% in `bench crane` (a backlog of
//!   30), 95% here; sequences, which fix part of the order and hold members back, leave
//!   less. The busy and hand-over shares say how much of the loss is rackd's own.
//! - *Zero inversions, within an aisle and across aisles*, is in reach at any transit
//!   times: rackd releases a member only once the member before it completed and the
//!   transit difference passed (`service::dispatch::gate`), which serialises a sequence at
//!   the cost of cranes waiting (the busy share) and of fewer jobs to pair (the travel).
//! - *No deadline missed that the offline schedule meets* compares with a schedule that
//!   relaxes a crane (see `site/offline.rs`: preemptive, no empty travel beyond the least,
//!   no hand-over). A tight deadline it meets can lie out of a real crane's reach by a job
//!   under way that cannot be stopped, or by a second tight job on the same crane: this
//!   goal's count is an upper bound on the misses rackd could have avoided.
//! - *rackd's CPU under 10% of one core at 40 aisles* is the x20 figure over 20 at the
//!   site's own pace (2.5% by the arithmetic above); at x20 itself it is near half a core,
//!   which no goal asks of it.

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
    /// A deadline with slack leaves this many mean jobs' time beside the job's own seconds
    /// (40: more than the backlog of 8 and the 30 times the travel planner may pass a job
    /// over, so that travel alone meets it).
    #[arg(long, default_value_t = 40.0)]
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
    ensure!(
        args.backlog > 0 && args.time_scale > 0.0 && args.jobs > 1,
        "--backlog, --time-scale and --jobs must be above 0 (jobs above 1)"
    );
    ensure!(
        !args.aisles.is_empty() && args.aisles.iter().all(|&n| n > 0),
        "--aisles: one count or more, each above 0"
    );
    let motion = Motion::default();
    report::machine(&args);
    let runtimes = Runtimes::new()?;
    let result = async {
        let mut all = Vec::new();
        for &aisles in &args.aisles {
            let workload = Arc::new(Workload::draw(&args, aisles, &motion));
            report::workload(&workload, &args);
            let mut runs = Vec::new();
            for mode in Mode::ALL {
                let run = run::one(&workload, mode, &args, &runtimes).await?;
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
