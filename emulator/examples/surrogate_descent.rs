//! A whole closed-loop powered descent with the surrogate, in one process (the reference
//! GNC called in this thread, no IPC), timed: the figure that matters for campaigns,
//! rather than one step's nanoseconds.
//!
//! ```text
//! cargo run --release -p oils-emulator --example surrogate_descent -- [RUNS] [MODEL.json]
//! ```
//!
//! Prints per run the wall time of the whole descent (plant, GNC and surrogate, from
//! building the plant to touchdown), the part spent in the surrogate's steps, and a
//! BLAKE3 hash of every thrust and mass the surrogate returned, so two builds can be
//! compared bit for bit.

use oils_emulator::config::ScenarioConfig;
use oils_emulator::devices::Devices;
use oils_emulator::plant::{Plant, PlantStatus};
use oils_emulator::propulsion::{
    build_surrogate, EngineCommand, Propulsion, PropulsionDiagnostics, PropulsionKind,
    PropulsionOutput, PropulsionSpec,
};
use oils_emulator::sanitize::sanitize;
use oils_onboard_stub::fsw::FlightSoftware;
use oils_onboard_stub::gnc::{GncConfig, ReferenceGnc};
use oils_shared::PacketHeader;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const DT_NS: u64 = 10_000_000;

/// What the surrogate's steps cost and returned over one descent.
#[derive(Default)]
struct Stats {
    in_steps: Duration,
    steps: u64,
    hash: String,
}

/// The surrogate with a stopwatch around its steps and a hash of what they return; the
/// figures go to `report` when the plant drops it.
struct Timed {
    inner: Box<dyn Propulsion>,
    in_steps: Duration,
    steps: u64,
    hash: blake3::Hasher,
    report: Arc<Mutex<Stats>>,
}

impl Drop for Timed {
    fn drop(&mut self) {
        *self.report.lock().expect("stats") = Stats {
            in_steps: self.in_steps,
            steps: self.steps,
            hash: self.hash.finalize().to_hex()[..16].to_string(),
        };
    }
}

impl Propulsion for Timed {
    fn name(&self) -> &'static str {
        self.inner.name()
    }
    fn step(&mut self, cmd: &EngineCommand, dt_ns: u64) -> PropulsionOutput {
        let t0 = Instant::now();
        let out = self.inner.step(cmd, dt_ns);
        self.in_steps += t0.elapsed();
        self.steps += 1;
        for v in out
            .thrust_n
            .iter()
            .chain(&[out.ejected_fuel_kg, out.ejected_ox_kg])
        {
            self.hash.update(&v.to_le_bytes());
        }
        out
    }
    fn output(&self) -> PropulsionOutput {
        self.inner.output()
    }
    fn diagnostics(&self) -> Option<PropulsionDiagnostics> {
        self.inner.diagnostics()
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let runs: usize = args.get(1).map_or(5, |s| s.parse().expect("RUNS"));
    let cfg = ScenarioConfig::default();
    let spec = PropulsionSpec {
        surrogate_model: args.get(2).map(Into::into),
        step_ns: Some(DT_NS),
        ..PropulsionSpec::new(PropulsionKind::Surrogate, &cfg.propulsion)
    };
    for run in 0..runs {
        let report = Arc::new(Mutex::new(Stats::default()));
        let t0 = Instant::now();
        let surrogate = build_surrogate(&spec).expect("model");
        let timed = Timed {
            inner: Box::new(surrogate),
            in_steps: Duration::ZERO,
            steps: 0,
            hash: blake3::Hasher::new(),
            report: report.clone(),
        };
        let mut plant = Plant::new(&cfg, Box::new(timed)).expect("plant");
        let mut devices = Devices::new(&cfg, 2024);
        let mut gnc = ReferenceGnc::new(GncConfig::default()).expect("gnc");
        let mut landed = None;
        for k in 0..200_000u64 {
            let tlm = devices.telemetry(&plant, PacketHeader::new(1, k, plant.time_ns()));
            let cmd = gnc.step(&tlm);
            if let PlantStatus::Touchdown(td) = plant.step(
                &sanitize(&cmd, cfg.propulsion.max_thrust_n, tlm.header.t_ns, DT_NS).0,
                DT_NS,
            ) {
                landed = Some(td);
                break;
            }
        }
        drop(plant);
        let wall = t0.elapsed();
        let s = report.lock().expect("stats");
        let td = landed.expect("no touchdown within 2000 s");
        println!(
            "run {run}: descent {:.3} s wall, surrogate steps {:.3} s ({} steps, {:.0} ns/step), \
             touchdown at {:.2} m/s, outputs {}",
            wall.as_secs_f64(),
            s.in_steps.as_secs_f64(),
            s.steps,
            s.in_steps.as_nanos() as f64 / s.steps.max(1) as f64,
            td.vertical_speed_mps,
            s.hash
        );
    }
}
