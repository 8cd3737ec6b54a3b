//! From the collected figures to the findings: which faults the evidence points at, and the
//! per-unit figures and plots of the report.

use super::{
    BINS, Bin, EVIDENCE, Finding, GARBAGE_SHARE, Health, LATENCY_POINTS, LatencyPoint, Report, STORM_MIN, STORM_SHARE,
    Tally, UnitHealth, ratio,
};

impl Health {
    /// The report.
    #[must_use]
    pub fn report(&self) -> Report {
        let mut findings = Vec::new();
        let mut push = |kind, unit, t: &Tally, summary: String| {
            if t.count > 0 {
                findings.push(Finding {
                    kind,
                    unit,
                    count: t.count,
                    first_t_ns: t.first,
                    last_t_ns: t.last,
                    summary,
                    evidence: t.evidence.clone(),
                });
            }
        };
        let total_bytes = self.noise_bytes + self.frame_bytes;
        let garbage = total_bytes > 64 && ratio(self.noise_bytes, total_bytes) > GARBAGE_SHARE;
        if garbage {
            let share = ratio(self.noise_bytes, total_bytes) * 100.0;
            push(
                "wrong_line_settings",
                None,
                &self.noise,
                format!(
                    "{share:.0} % of the bytes belong to no valid frame: the baud rate, parity or mode is probably not the line's (try mbtap scan)"
                ),
            );
        } else {
            let n = self.noise.count;
            push(
                "noise",
                None,
                &self.noise,
                format!("{n} burst(s) of bytes that belong to no frame: interference, termination or biasing"),
            );
        }
        // Check errors on every unit that answers at all point at the bus, not a device.
        let answering: Vec<u8> = self.units.iter().filter(|(_, u)| u.ok > 0).map(|(&k, _)| k).collect();
        let failing: Vec<u8> = self.units.iter().filter(|(_, u)| u.bad_response.count > 0).map(|(&k, _)| k).collect();
        let bus_wide = answering.len() > 1 && answering.iter().all(|u| failing.contains(u));
        if bus_wide && !garbage {
            let mut all = Tally::default();
            let mut times: Vec<u64> =
                self.units.values().flat_map(|u| u.bad_response.evidence.iter().copied()).collect();
            times.sort_unstable();
            for u in self.units.values() {
                all.count += u.bad_response.count;
                all.first = if all.first == 0 { u.bad_response.first } else { all.first.min(u.bad_response.first) };
                all.last = all.last.max(u.bad_response.last);
            }
            all.evidence = times.into_iter().take(EVIDENCE).collect();
            push(
                "check_errors",
                None,
                &all,
                "answers with failed checks from every unit: the cabling, termination or grounding of the bus".into(),
            );
        }
        push(
            "fast_master",
            None,
            &self.fast_master,
            "requests sent less than t3.5 after the previous frame (Serial Line v1.02 §2.5.1.1): slaves may merge or drop them".into(),
        );
        let mut units = Vec::new();
        for (&unit, u) in &self.units {
            if !bus_wide && !garbage {
                let n = u.bad_response.count;
                push(
                    "check_errors",
                    Some(unit),
                    &u.bad_response,
                    format!("{n} answer(s) from unit {unit} failed their check"),
                );
            }
            push(
                "implausible_jump",
                Some(unit),
                &u.jumps,
                format!(
                    "unit {unit} reports readings that move more than half their documented range between two reads"
                ),
            );
            push(
                "duplicate_address",
                Some(unit),
                &u.doubled,
                format!("unit {unit} answers twice to one request: two devices are set to address {unit}"),
            );
            push(
                "gap_inside_frame",
                Some(unit),
                &u.gaps,
                format!(
                    "unit {unit} pauses inside its frames longer than t1.5: a slow device or a gateway that splits frames"
                ),
            );
            let nr = u.no_response.count;
            let pattern = if u.ok == 0 { "never answers" } else { "answers only intermittently" };
            push(
                "no_response",
                Some(unit),
                &u.no_response,
                format!("unit {unit} {pattern}: {nr} of {} request(s) unanswered", u.transactions),
            );
            let exceptions: u64 = u.exceptions.values().sum();
            if exceptions >= STORM_MIN && ratio(exceptions, u.transactions) > STORM_SHARE {
                let codes: Vec<String> = u.exceptions.iter().map(|(c, n)| format!("0x{c:02X}×{n}")).collect();
                push(
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
            push(
                "value_out_of_range",
                Some(unit),
                &u.out_of_range,
                format!("unit {unit} reports values outside its profile's range"),
            );
            let mut latencies = u.latencies.clone();
            latencies.sort_unstable();
            let pct = |p: usize| latencies.get((latencies.len().saturating_sub(1)) * p / 100).copied();
            units.push(UnitHealth {
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
                    100.0 - ratio(u.no_response.count + u.bad_response.count, u.transactions) * 100.0
                },
                latency_p50_ns: pct(50),
                latency_p99_ns: pct(99),
                latency_max_ns: latencies.last().copied(),
            });
        }
        findings.sort_by_key(|f| (f.first_t_ns, f.kind));
        let (timeline, latencies) = self.plots();
        Report {
            first_t_ns: self.first,
            last_t_ns: self.last,
            frames: self.frames,
            bad_frames: self.bad_frames,
            noise_bytes: self.noise_bytes,
            frame_bytes: self.frame_bytes,
            transactions: self.transactions,
            units,
            findings,
            timeline,
            latencies,
        }
    }

    fn plots(&self) -> (Vec<Bin>, Vec<LatencyPoint>) {
        let (Some(first), Some(last)) = (self.first, self.last) else { return (Vec::new(), Vec::new()) };
        let width = (last - first) / BINS as u64 + 1;
        let mut bins: Vec<Bin> =
            (0..BINS as u64).map(|i| Bin { t_start_ns: first + i * width, ..Bin::default() }).collect();
        let bin = |t: u64| usize::try_from((t.saturating_sub(first)) / width).unwrap_or(0).min(BINS - 1);
        for &(t, _, latency, failed) in &self.samples {
            let b = &mut bins[bin(t)];
            b.transactions += 1;
            b.errors += u64::from(failed);
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
            .filter_map(|&(t_ns, unit, l, _)| l.map(|latency_ns| LatencyPoint { t_ns, unit, latency_ns }))
            .collect();
        let step = with_latency.len().div_ceil(LATENCY_POINTS).max(1);
        (bins, with_latency.into_iter().step_by(step).collect())
    }
}
