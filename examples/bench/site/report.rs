//! What `bench site` prints: the machine, each workload, a row per run, the comparisons
//! within one aisle count, and the goals over all of them.

use std::sync::Arc;

use super::SiteArgs;
use super::figures::Figures;
use super::run::Run;
use super::workload::Workload;

/// The runs of one aisle count, in [`Mode::ALL`]'s order.
type Runs = Vec<(Run, Figures)>;

/// The machine and the time scale.
pub fn machine(args: &SiteArgs) {
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let load: Vec<&str> = load.split_whitespace().take(3).collect();
    println!(
        "bench site: {} cores, load average {} at the start; time x{}, rackd's crane poll {} ms and heartbeat 500 ms at the site's pace ({:.1} ms and {:.1} ms of wall time)",
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        load.join(" "),
        args.time_scale,
        args.poll_ms,
        args.poll_ms as f64 / args.time_scale,
        500.0 / args.time_scale,
    );
}

/// One aisle count's workload and the machines' bound.
pub fn workload(w: &Workload, args: &SiteArgs) {
    let (deadlines, tight, members) = w.counts();
    let stores = w.jobs.iter().filter(|j| matches!(j.kind, super::workload::Kind::Store(_))).count();
    let transits: Vec<f64> =
        w.stations.iter().flat_map(|s| (1..=w.aisles).map(move |a| s.transit(a))).collect();
    println!();
    println!(
        "{} aisles (2 rows x {} bays x {} levels, single-deep, {:.0}% full), {} station{} (transit {:.0} to {:.0} s); {} jobs: {} stores, {} retrieves ({} in {} sequences), {} deadlines ({} tight); backlog {} per aisle",
        w.aisles,
        args.bays,
        args.levels,
        args.fill * 100.0,
        w.stations.len(),
        if w.stations.len() == 1 { "" } else { "s" },
        transits.iter().copied().fold(f64::INFINITY, f64::min),
        transits.iter().copied().fold(0.0, f64::max),
        w.jobs.len(),
        stores,
        w.jobs.len() - stores,
        members,
        w.sequences.len(),
        deadlines,
        tight,
        args.backlog,
    );
    println!(
        "machines' bound: {:.0} jobs/h (the sum over the cranes of 3600 s / the least crane seconds per job of its share; {:.1} s per job over the site)",
        bound(w),
        w.mean_cycle()
    );
    println!(
        "{:<12} {:>7} {:>6} {:>11} {:>9} {:>10} {:>12} {:>13} {:>13} {:>8} {:>8} {:>6}",
        "run",
        "jobs/h",
        "bound",
        "busy/handov",
        "empty m",
        "inversions",
        "(in/across)",
        "late (t/s)",
        "latency ms",
        "rackd",
        "ms/job",
        "wall"
    );
}

/// The machines' bound, jobs per simulated hour.
pub fn bound(w: &Workload) -> f64 {
    w.bounds.iter().filter(|b| b.jobs > 0).map(|b| 3600.0 / b.per_cycle()).sum()
}

/// One run's row.
pub fn row(run: &Run, f: &Figures, w: &Workload) {
    let ms = |q: f64| f.latency.value_at_quantile(q) as f64 / 1000.0;
    let inv = &f.inversions;
    let d = &f.deadlines;
    println!(
        "{:<12} {:>7.0} {:>5.1}% {:>11} {:>9.0} {:>10} {:>12} {:>13} {:>13} {:>7.1}% {:>8.2} {:>5.0}s",
        run.mode.name(),
        f.throughput,
        100.0 * f.throughput / bound(w),
        format!("{:.1}%/{:.1}%", 100.0 * f.busy, 100.0 * f.dispatch),
        f.empty_m,
        inv.within + inv.across,
        format!("{}/{}", inv.within, inv.across),
        format!("{}+{} of {}", d.missed.0, d.missed.1, d.jobs.0),
        format!("{:.1}/{:.1}", ms(0.5), ms(0.99)),
        100.0 * f.cpu.0,
        1000.0 * f.cpu.2,
        run.wall.as_secs_f64(),
    );
    if !f.failed.is_empty() {
        println!("  not completed: {}", f.failed.join("; "));
    }
}

/// The comparisons within one aisle count.
pub fn compare(runs: &Runs, w: &Workload, args: &SiteArgs) {
    let [(_, plain), (_, slack), (orders_run, orders)] = runs.as_slice() else { return };
    let ratio = |a: f64, b: f64| a / b.max(f64::EPSILON);
    println!(
        "empty travel against travel only: slack only {:.3}x, orders {:.3}x; dual cycles (a retrieve after a store): {:.0}%, {:.0}%, {:.0}% of the stores",
        ratio(slack.empty_m, plain.empty_m),
        ratio(orders.empty_m, plain.empty_m),
        100.0 * plain.dual,
        100.0 * slack.dual,
        100.0 * orders.dual,
    );
    for (name, f) in [("travel only", plain), ("orders", orders)] {
        let stations: Vec<String> = f
            .inversions
            .by_station
            .iter()
            .map(|(s, (within, across))| format!("station {s} {within}/{across}"))
            .collect();
        println!(
            "inversions ({name}), within an aisle/across aisles, of {}/{} pairs: {}",
            f.inversions.pairs.0,
            f.inversions.pairs.1,
            stations.join(", ")
        );
    }
    for (name, f) in [("travel only", plain), ("slack only", slack), ("orders", orders)] {
        let d = &f.deadlines;
        let mut late = d.late_by.clone();
        late.sort_by(f64::total_cmp);
        let by = match late.as_slice() {
            [] => String::new(),
            l => format!(", late by {:.0} s (median) to {:.0} s", l[l.len() / 2], l[l.len() - 1]),
        };
        println!(
            "deadlines ({name}): {} of {} missed ({} of {} tight{by}); offline schedule {} (no schedule fewer than {}); missed by rackd, met offline: {}",
            d.missed.0 + d.missed.1,
            d.jobs.0,
            d.missed.0,
            d.jobs.1,
            d.offline,
            d.at_least,
            d.offline_met
        );
    }
    let p50 = orders.latency.value_at_quantile(0.5) as f64 / 1e6;
    let p99 = orders.latency.value_at_quantile(0.99) as f64 / 1e6;
    println!(
        "dispatch latency (orders): p50 {:.1} ms, p99 {:.1} ms of wall time = {:.2} s and {:.2} s simulated, {:.1}% and {:.1}% of a {:.1} s job",
        p50 * 1000.0,
        p99 * 1000.0,
        p50 * args.time_scale,
        p99 * args.time_scale,
        100.0 * p50 * args.time_scale / w.mean_cycle(),
        100.0 * p99 * args.time_scale / w.mean_cycle(),
        w.mean_cycle(),
    );
    let (busy, idle, per_job) = orders.cpu;
    println!(
        "rackd's CPU (orders): {:.1}% of a core at x{} ({:.1}% with the cranes idle), {:.2} ms per job; at the site's own pace {:.2}%; the simulators {:.0}% ({:.0}% idle); run's wall {:.0} s",
        100.0 * busy,
        args.time_scale,
        100.0 * idle,
        1000.0 * per_job,
        100.0 * busy / args.time_scale,
        100.0 * orders.sims_cpu.0,
        100.0 * orders.sims_cpu.1,
        orders_run.wall.as_secs_f64(),
    );
}

/// The goals, each with its bound, over every aisle count run.
pub fn goals(all: &[(Arc<Workload>, Runs)], args: &SiteArgs) {
    println!();
    println!(
        "rackd by the number of aisles (orders runs; CPU at x{}, and at the site's own pace):",
        args.time_scale
    );
    println!(
        "{:>6} {:>10} {:>10} {:>10} {:>12} {:>22} {:>14}",
        "aisles", "CPU", "idle", "site pace", "CPU per job", "dispatch p50/p99 ms", "simulated s"
    );
    for (w, runs) in all {
        let f = &runs[2].1;
        let q = |q: f64| f.latency.value_at_quantile(q) as f64 / 1000.0;
        println!(
            "{:>6} {:>9.1}% {:>9.1}% {:>9.2}% {:>9.2} ms {:>22} {:>14}",
            w.aisles,
            100.0 * f.cpu.0,
            100.0 * f.cpu.1,
            100.0 * f.cpu.0 / args.time_scale,
            1000.0 * f.cpu.2,
            format!("{:.1}/{:.1}", q(0.5), q(0.99)),
            format!("{:.2}/{:.2}", q(0.5) * args.time_scale / 1000.0, q(0.99) * args.time_scale / 1000.0),
        );
    }
    println!();
    println!("goals (orders run unless said):");
    let each = |pick: &dyn Fn(&Workload, &Runs) -> (String, bool)| {
        let mut pass = true;
        let shown: Vec<String> = all
            .iter()
            .map(|(w, runs)| {
                let (text, ok) = pick(w, runs);
                pass &= ok;
                format!("{} aisles {text}", w.aisles)
            })
            .collect();
        (shown.join(", "), pass)
    };
    fn orders(runs: &Runs) -> &Figures {
        &runs[2].1
    }
    let lines: Vec<(&str, (String, bool))> = vec![
        (
            "zero inversions within an aisle (bound 0)",
            each(&|_, r| (orders(r).inversions.within.to_string(), orders(r).inversions.within == 0)),
        ),
        (
            "zero inversions across aisles (bound 0: the release rule allows none at any transit)",
            each(&|_, r| (orders(r).inversions.across.to_string(), orders(r).inversions.across == 0)),
        ),
        (
            "no deadline missed that the offline schedule meets",
            each(&|_, r| (orders(r).deadlines.offline_met.to_string(), orders(r).deadlines.offline_met == 0)),
        ),
        (
            "slack deadlines: empty travel within 5% of travel only",
            each(&|_, r| {
                let x = r[1].1.empty_m / r[0].1.empty_m.max(f64::EPSILON);
                (format!("{x:.3}x"), x <= 1.05)
            }),
        ),
    ];
    for (goal, (shown, pass)) in lines {
        println!("{} {goal}: {shown}", if pass { "PASS" } else { "FAIL" });
    }
    match all.iter().find(|(w, _)| w.aisles == 40) {
        Some((w, runs)) => {
            let f = orders(runs);
            let share = f.throughput / bound(w);
            println!(
                "{} at 40 aisles, throughput >= 95% of the machines' bound: {:.1}% = busy {:.1}% of the cranes' time x the planner's {:.1}% of perfect foresight (hand-overs {:.1}% of the time)",
                if share >= 0.95 { "PASS" } else { "FAIL" },
                100.0 * share,
                100.0 * f.busy,
                100.0 * share / f.busy.max(f64::EPSILON),
                100.0 * f.dispatch,
            );
            let pace = f.cpu.0 / args.time_scale;
            println!(
                "{} at 40 aisles, rackd's CPU < 10% of one core at the site's own pace: {:.2}% ({:.1}% at x{})",
                if pace < 0.1 { "PASS" } else { "FAIL" },
                100.0 * pace,
                100.0 * f.cpu.0,
                args.time_scale
            );
        }
        None => println!("(the goals at 40 aisles: not run; --aisles 1,10,40 runs them)"),
    }
}
