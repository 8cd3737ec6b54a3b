//! From the collected figures to the findings: which faults the evidence points at, and the
//! per-unit figures and plots of the report.

use super::{
    BINS, Bin, Class, Finding, GARBAGE_SHARE, Health, LATENCY_POINTS, LatencyPoint, Report, STORM_MIN, STORM_SHARE,
    Tally, UnitHealth, clock, ratio,
};

/// Check errors are judged for clustering only from this many on.
const CLUSTER_MIN: u64 = 5;
/// Windows the capture is cut into to see whether check errors cluster.
const CLUSTER_WINDOWS: usize = 20;
/// The busiest tenth of the windows holding this share of the errors (and not merely the
/// traffic) is a burst pattern.
const BURST_SHARE: f64 = 0.5;

/// The findings as they are found: a tally that counted nothing is no finding.
struct Found(Vec<Finding>);

impl Found {
    fn push(&mut self, kind: &'static str, unit: Option<u8>, t: &Tally, summary: String) {
        if t.count > 0 {
            self.0.push(Finding {
                kind,
                unit,
                count: t.count,
                first_t_ns: t.first,
                last_t_ns: t.last,
                summary,
                evidence: t.evidence.clone(),
            });
        }
    }
}

/// What the line as a whole showed, which decides how its units' findings are said.
#[derive(Clone, Copy)]
struct LineWide {
    /// Mostly bytes of no valid frame: the line settings are wrong, nothing else is said of it.
    garbage: bool,
    /// Check errors on every unit that answers at all: the bus, not a device.
    check_errors: bool,
    /// The shortest fault the reads could prove.
    resolution: u64,
}

impl Health {
    /// The report.
    #[must_use]
    pub fn report(&self) -> Report {
        let mut found = Found(Vec::new());
        let line = self.line_findings(&mut found);
        let mut units = Vec::new();
        for (&unit, u) in &self.units {
            self.unit_findings(&mut found, unit, u, line);
            units.push(unit_health(unit, u));
        }
        let mut findings = found.0;
        if !self.in_step {
            // Noise or check errors would only restate it; mostly garbage still points at the
            // line settings.
            findings.retain(|f| matches!(f.kind, "no_valid_frames" | "wrong_line_settings"));
        }
        findings.sort_by_key(|f| (f.first_t_ns, f.kind));
        let (timeline, latencies) = self.plots();
        Report {
            first_t_ns: self.first,
            last_t_ns: self.last,
            frames: self.frames,
            bad_frames: self.bad_frames,
            noise_bytes: self.noise_bytes,
            noise_bursts: self.noise.count,
            stray_frames: self.stray.count,
            stray_bytes: self.stray_bytes,
            cut_at_start_bytes: self.cut_at_start,
            frame_bytes: self.frame_bytes,
            transactions: self.transactions,
            units,
            findings,
            timeline,
            latencies,
            line: None,
            observers: Vec::new(),
            limits: self.limits(line.resolution),
        }
    }

    /// How check errors came, for a finding's summary: `; in bursts …`, or nothing.
    fn pattern(&self, unit: Option<u8>) -> String {
        self.clustering(unit).map_or_else(String::new, |p| format!("; {p}"))
    }

    /// The findings of the line as a whole: nothing valid heard, wrong settings or noise, check
    /// errors of the bus, a second or fast master, the master's turnaround glitches.
    fn line_findings(&self, found: &mut Found) -> LineWide {
        // Nothing heard is not a healthy bus: say what was heard, and nothing else.
        if !self.in_step {
            let heard = self.noise_bytes + self.frame_bytes + self.cut_at_start;
            let summary = if heard == 0 {
                "no valid frame: nothing was heard at all — a silent line (no master polling, the wrong port, A and B swapped or unconnected, the adapter's receiver off)".to_owned()
            } else {
                format!(
                    "no valid frame in {heard} byte(s) heard: the wrong baud rate, parity or mode (try mbtap scan), A and B swapped, or something that does not speak Modbus RTU/ASCII"
                )
            };
            let t = Tally {
                count: heard.max(1),
                first: self.first.unwrap_or(0),
                last: self.last.unwrap_or(0),
                evidence: self.first.into_iter().collect(),
            };
            found.push("no_valid_frames", None, &t, summary);
        }
        // Bytes that belong to no valid frame: noise and frames that failed with nothing awaited.
        let junk = self.noise_bytes + self.stray_bytes;
        let total_bytes = self.noise_bytes + self.frame_bytes;
        let garbage = total_bytes > 64 && ratio(junk, total_bytes) > GARBAGE_SHARE;
        let noise_and_strays = self.noise.merged(&self.stray);
        if garbage {
            let share = ratio(junk, total_bytes) * 100.0;
            found.push(
                "wrong_line_settings",
                None,
                &noise_and_strays,
                format!(
                    "{share:.0} % of the bytes belong to no valid frame: the baud rate, parity or mode is probably not the line's (try mbtap scan)"
                ),
            );
        } else {
            let (n, m) = (self.noise.count, self.stray.count);
            let what = match (n, m) {
                (_, 0) => format!("{n} burst(s) of bytes that belong to no frame"),
                (0, _) => format!("{m} frame(s) that failed their check with no answer awaited"),
                _ => format!(
                    "{n} burst(s) of bytes that belong to no frame and {m} frame(s) that failed their check with no answer awaited"
                ),
            };
            found.push("noise", None, &noise_and_strays, format!("{what}: interference, termination or biasing"));
        }
        // Check errors on every unit that answers at all point at the bus, not a device.
        let answering: Vec<u8> = self.units.iter().filter(|(_, u)| u.ok > 0).map(|(&k, _)| k).collect();
        let failing: Vec<u8> = self.units.iter().filter(|(_, u)| u.bad_response.count > 0).map(|(&k, _)| k).collect();
        let bus_wide = answering.len() > 1 && answering.iter().all(|u| failing.contains(u));
        if bus_wide && !garbage {
            let all = self.units.values().fold(self.bus_bad.clone(), |all, u| all.merged(&u.bad_response));
            found.push(
                "check_errors",
                None,
                &all,
                format!(
                    "answers with failed checks from every unit: the cabling, termination or grounding of the bus{}",
                    self.pattern(None)
                ),
            );
        }
        if !bus_wide && !garbage {
            found.push(
                "check_errors",
                None,
                &self.bus_bad,
                format!(
                    "{} frame(s) in place of an answer failed their check with a damaged address: the bus garbled them, no unit can be named{}",
                    self.bus_bad.count,
                    self.pattern(None)
                ),
            );
        }
        found.push(
            "second_master",
            None,
            &self.second_master,
            "requests went out while another request's answer was still due, and that answer then came: a second master shares the line (their requests will collide sooner or later)".into(),
        );
        let resolution = self.resolution_ns();
        found.push(
            "fast_master",
            None,
            &self.fast_master.proven(resolution),
            "requests sent less than t3.5 after the previous frame (Serial Line v1.02 §2.5.1.1): slaves may merge or drop them".into(),
        );
        found.push(
            "turnaround_glitch",
            None,
            &self.master_glitches,
            glitch_summary("the master", self.master_glitches.count, self.master_sent),
        );
        LineWide { garbage, check_errors: bus_wide, resolution }
    }

    /// One unit's findings, said as the line allows.
    fn unit_findings(&self, found: &mut Found, unit: u8, u: &super::UnitState, line: LineWide) {
        let LineWide { garbage, check_errors: bus_wide, resolution } = line;
        found.push(
            "turnaround_glitch",
            Some(unit),
            &u.glitches,
            glitch_summary(&format!("unit {unit}"), u.glitches.count, u.sent),
        );
        if !bus_wide && !garbage {
            let n = u.bad_response.count;
            let collided = if u.collided.count > 0 {
                format!(" ({} of them look like collisions: see duplicate_address)", u.collided.count)
            } else {
                String::new()
            };
            found.push(
                "check_errors",
                Some(unit),
                &u.bad_response,
                format!("{n} answer(s) from unit {unit} failed their check{collided}{}", self.pattern(Some(unit))),
            );
        }
        found.push(
            "implausible_jump",
            Some(unit),
            &u.jumps,
            format!("unit {unit} reports readings that move more than half their documented range between two reads"),
        );
        let how = match (u.doubled.count, u.collided.count) {
            (0, c) => format!("{c} answer(s) garbled as two answers on top of each other (bits only cleared)"),
            (d, 0) => format!("{d} request(s) answered twice"),
            (d, c) => format!("{d} request(s) answered twice, {c} answer(s) garbled by a second one"),
        };
        found.push(
            "duplicate_address",
            Some(unit),
            &u.doubled.merged(&u.collided),
            format!("unit {unit}: {how} — two devices are set to address {unit}"),
        );
        if let Some(wait) = u.master_wait_min {
            found.push(
                "late_answer",
                Some(unit),
                &u.late,
                format!(
                    "unit {unit} answered after its master had moved on (answers up to {:.1} ms after the request; the master waited only {:.1} ms): raise the master's response timeout",
                    ratio(u.late_latency_max, 1_000_000),
                    ratio(wait, 1_000_000)
                ),
            );
        }
        found.push(
            "fast_answer",
            Some(unit),
            &u.fast_answers.proven(resolution),
            format!(
                "unit {unit} answers less than t3.5 after the request (Serial Line v1.02 §2.5.1.1): other devices may take its answer for part of the request"
            ),
        );
        found.push(
            "gap_inside_frame",
            Some(unit),
            &u.gaps.proven(resolution),
            format!(
                "unit {unit} pauses inside its frames longer than t1.5: a slow device or a gateway that splits frames"
            ),
        );
        let nr = u.no_response.count;
        let pattern = if u.ok == 0 { "never answers" } else { "answers only intermittently" };
        found.push(
            "no_response",
            Some(unit),
            &u.no_response,
            format!("unit {unit} {pattern}: {nr} of {} request(s) unanswered", u.transactions),
        );
        let exceptions: u64 = u.exceptions.values().sum();
        if exceptions >= STORM_MIN && ratio(exceptions, u.transactions) > STORM_SHARE {
            let codes: Vec<String> = u.exceptions.iter().map(|(c, n)| format!("0x{c:02X}×{n}")).collect();
            found.push(
                "exception_storm",
                Some(unit),
                &u.exception_tally,
                format!(
                    "unit {unit} answers {exceptions} of {} requests with exceptions ({}): polling what the device does not have?",
                    u.transactions,
                    codes.join(", ")
                ),
            );
        }
        found.push(
            "value_out_of_range",
            Some(unit),
            &u.out_of_range,
            format!("unit {unit} reports values outside its profile's range: {}", u.out_of_range_examples.join("; ")),
        );
    }
}

/// One unit's figures in the report.
fn unit_health(unit: u8, u: &super::UnitState) -> UnitHealth {
    let mut periods = u.periods.clone();
    periods.sort_unstable();
    let mut latencies = u.latencies.clone();
    latencies.sort_unstable();
    let pct = |p: usize| latencies.get((latencies.len().saturating_sub(1)) * p / 100).copied();
    UnitHealth {
        unit,
        transactions: u.transactions,
        ok: u.ok,
        exceptions: u.exceptions.clone(),
        no_response: u.no_response.count,
        bad_responses: u.bad_response.count,
        // Answered (normally or with an exception) out of asked.
        availability_percent: if u.transactions == 0 {
            0.0
        } else {
            100.0 - ratio(u.no_response.count + u.bad_response.count + u.unclear, u.transactions) * 100.0
        },
        latency_p50_ns: pct(50),
        latency_p99_ns: pct(99),
        latency_max_ns: latencies.last().copied(),
        poll_period_ns: periods.get(periods.len() / 2).copied(),
    }
}

/// A turnaround glitch finding's words.
fn glitch_summary(who: &str, n: u64, sent: u64) -> String {
    format!(
        "a garbage byte follows {n} of {sent} frames from {who} at driver turnaround: missing or weak fail-safe biasing (Serial Line v1.02 §3.4: polarize the line, e.g. 450–650 Ω pull-up/pull-down at one point)"
    )
}

impl Health {
    /// What these reads could not resolve, said once instead of as findings.
    fn limits(&self, resolution: u64) -> Vec<String> {
        let unproven = |m: &super::margins::Margins| m.total() - m.proven(resolution).count;
        let gaps: u64 = self.units.values().map(|u| unproven(&u.gaps)).sum();
        let fast: u64 =
            unproven(&self.fast_master) + self.units.values().map(|u| unproven(&u.fast_answers)).sum::<u64>();
        if gaps + fast == 0 {
            return Vec::new();
        }
        let ms = ratio(resolution, 1_000_000);
        let mut what = Vec::new();
        if gaps > 0 {
            what.push(format!("{gaps} apparent pause(s) inside frames"));
        }
        if fast > 0 {
            what.push(format!("{fast} apparent silence(s) shorter than t3.5 between frames"));
        }
        vec![format!(
            "timing: {} are within what these reads cannot resolve: timing faults shorter than {ms:.1} ms (the observer's latency, a sixteenth more, and a character where a read holds several bytes) cannot be seen through them; use an adapter that timestamps each byte, or give the adapter's latency with --latency-ms",
            what.join(" and ")
        )]
    }

    fn plots(&self) -> (Vec<Bin>, Vec<LatencyPoint>) {
        let (Some(first), Some(last)) = (self.first, self.last) else { return (Vec::new(), Vec::new()) };
        let width = (last - first) / BINS as u64 + 1;
        let mut bins: Vec<Bin> =
            (0..BINS as u64).map(|i| Bin { t_start_ns: first + i * width, ..Bin::default() }).collect();
        let bin = |t: u64| usize::try_from((t.saturating_sub(first)) / width).unwrap_or(0).min(BINS - 1);
        for &super::Sample { t, latency, class, .. } in &self.samples {
            let b = &mut bins[bin(t)];
            b.transactions += 1;
            b.errors += u64::from(class != Class::Answered);
            if let Some(l) = latency {
                b.latency_max_ns = Some(b.latency_max_ns.map_or(l, |m| m.max(l)));
            }
        }
        for &t in &self.noise_times {
            bins[bin(t)].errors += 1;
        }
        let with_latency: Vec<LatencyPoint> = self
            .samples
            .iter()
            .filter_map(|s| s.latency.map(|latency_ns| LatencyPoint { t_ns: s.t, unit: s.unit, latency_ns }))
            .collect();
        let step = with_latency.len().div_ceil(LATENCY_POINTS).max(1);
        (bins, with_latency.into_iter().step_by(step).collect())
    }

    /// Whether failed checks (of `unit`, or of every unit) come in bursts or steadily, in words.
    fn clustering(&self, unit: Option<u8>) -> Option<String> {
        let (Some(first), Some(last)) = (self.first, self.last) else { return None };
        let width = (last - first) / CLUSTER_WINDOWS as u64 + 1;
        let mut windows = [(0u64, 0u64); CLUSTER_WINDOWS];
        let mut failed = 0u64;
        let mut traffic = 0u64;
        for s in self.samples.iter().filter(|s| unit.is_none_or(|u| s.unit == u)) {
            let w = usize::try_from((s.t.saturating_sub(first)) / width).unwrap_or(0).min(CLUSTER_WINDOWS - 1);
            windows[w].1 += 1;
            traffic += 1;
            if s.class == Class::FailedCheck {
                windows[w].0 += 1;
                failed += 1;
            }
        }
        if failed < CLUSTER_MIN {
            return None;
        }
        let mut order: Vec<usize> = (0..CLUSTER_WINDOWS).collect();
        order.sort_by_key(|&w| std::cmp::Reverse(windows[w].0));
        let top = &order[..CLUSTER_WINDOWS / 10];
        let in_top: u64 = top.iter().map(|&w| windows[w].0).sum();
        let traffic_in_top: u64 = top.iter().map(|&w| windows[w].1).sum();
        let share = ratio(in_top, failed);
        let traffic_share = ratio(traffic_in_top, traffic);
        // Errors that merely follow the traffic are not a burst.
        Some(if share >= BURST_SHARE && traffic_share < share / 2.0 {
            let peak = first + top[0] as u64 * width;
            format!(
                "in bursts: {:.0} % of them within a tenth of the time (around {}) — something intermittent: a motor or contactor switching, a welder, a radio",
                share * 100.0,
                clock(peak)
            )
        } else {
            "spread over the whole capture — a steady fault: termination, biasing, grounding or cable length".into()
        })
    }
}
