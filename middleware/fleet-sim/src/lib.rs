//! A fleet to try recall management on (`autoplug fleet simulate`): N virtual cars, each
//! with its own bus, its own gateway (the same [`Watch`] with its tester and
//! [`FleetLink`] as `autoplug gateway --transmit --fleet`) and its own MQTT session,
//! driven headless and faster than real time by simulated drivers.
//!
//! The fleet is planned from a seed ([`plan`]): distinct VINs (ISO 3779 check digit) and
//! ECU serials, a mix of software releases per ECU, a share of cars with the faulty cruise
//! release [`FAULTY_CRUISE`], and varied drives (speed, with or without cruise control,
//! how long). The simulation knows the truth the fleet has to find: which car ran faulty
//! cruise software with cruise engaged long enough to show it ([`DriveTruth`]).
//!
//! A car's life is drives and parks. A drive: the ignition on, away from standstill to the
//! planned speed, cruise engaged (or the speed held by foot), a stop, the ignition off (the
//! ECUs fall silent and the trip ends on the bus's silence). Parked, the gateway stays
//! awake on its link to the fleet; when the fleet offers an update the simulated driver
//! answers at once, and with consent the ignition goes on for the gateway to flash while
//! the car stands, then off again. A car can also be taken offline (its MQTT connection
//! closed, its session kept at the broker) and brought back.
//!
//! Cars are not `Send` (the tester's outbox is shared with the source on one thread), so
//! each worker thread builds its share of the fleet and keeps it; the caller hands all
//! workers the same order and waits for their answers.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use autoplug_can::Node;
use autoplug_fleet::campaign::CampaignReport;
use autoplug_gateway::{Pipeline, Strictness};
use autoplug_image::{SoftwareVariant, Version};
use autoplug_vin::Vin;
use autoplug_virtual_car::car::VirtualCar;
use autoplug_virtual_car::driver::HeldControls;
use autoplug_virtual_car::scenario::{Button, Scenario};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use autoplug_fleet_agent::link::{FleetConfig, FleetLink};
use autoplug_live::sources::{Transmitting, VirtualCarSource};
use autoplug_live::watch::Watch;
use autoplug_tester::bus_tester::BusTester;
use autoplug_tester::bus_tester::Outbox;
use autoplug_tester::names::ECUS;
use autoplug_tester::TesterConfig;

/// The cruise release with the speed oscillation (the report's faulty software).
pub const FAULTY_CRUISE: Version = Version::new(1, 1, 0);
/// The cruise releases in the field and their shares: the faulty one among them.
pub const CRUISE_RELEASES: [(Version, f64); 3] = [
    (Version::new(1, 0, 0), 0.35),
    (Version::new(1, 0, 2), 0.30),
    (FAULTY_CRUISE, 0.35),
];
/// The ABS releases in the field and their shares.
pub const ABS_RELEASES: [(Version, f64); 2] =
    [(Version::new(1, 0, 0), 0.6), (Version::new(1, 0, 1), 0.4)];
/// The engine releases in the field and their shares.
pub const ENGINE_RELEASES: [(Version, f64); 2] =
    [(Version::new(1, 0, 0), 0.5), (Version::new(1, 0, 3), 0.5)];
/// Share of drives with cruise control engaged.
pub const CRUISE_DRIVE_SHARE: f64 = 0.6;
/// Cruise stays engaged at least this long on a drive that uses it, s: the gateway's
/// cruise routine needs 8 s to settle and 5 s of evidence.
pub const MIN_CRUISE_S: f64 = 20.0;
/// Simulated time a car may live, s (the longest a scenario may run).
const CAR_LIFE_S: f64 = 3600.0;
/// A drive's time besides holding its speed, s (start, accelerate, brake, stand), roughly.
const DRIVE_OVERHEAD_S: f64 = 30.0;
/// How often the gateway reads the trouble codes, µs of bus time.
const DTC_INTERVAL_US: u64 = 60_000_000;
/// Bus time the ignition stays off after a drive before the car counts as parked: the
/// trip ends on 5 s of silence.
const IGNITION_OFF_US: u64 = 6_000_000;
/// Simulated time a car runs per turn while others wait their turn, µs.
const SLICE_US: u64 = 100_000;
/// Polls of the car's bus between two moves of the driver's hands (a few ms of bus time).
const POLLS_PER_RUN: u32 = 32;

/// What to simulate.
#[derive(Clone, Debug)]
pub struct FleetPlan {
    /// How many cars.
    pub vehicles: usize,
    /// The seed everything is drawn from: the same plan gives the same fleet.
    pub seed: u64,
    /// Drives per car planned (each [`Order::Drive`] takes the next).
    pub drives: usize,
    /// Share of drivers who decline an update.
    pub decline_share: f64,
    /// The serial of the first car's VIN (the last six characters); the others follow.
    pub first_serial: u32,
    /// Make every drive last about this many minutes (the speed held that much longer;
    /// the benchmark's 10-minute drives). `None`: drives of half a minute to a minute.
    pub drive_minutes: Option<f64>,
}

impl FleetPlan {
    /// `vehicles` cars from `seed`, two drives each, every driver agreeing to updates.
    pub fn new(vehicles: usize, seed: u64) -> Self {
        Self {
            vehicles,
            seed,
            drives: 2,
            decline_share: 0.0,
            first_serial: 100_000,
            drive_minutes: None,
        }
    }
}

/// One drive of a car.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Drive {
    /// The speed the driver goes to, km/h.
    pub target_kmh: f64,
    /// With cruise control engaged at that speed.
    pub cruise: bool,
    /// How long the speed is held, s.
    pub hold_s: f64,
    /// The engine-mode switch.
    pub economy: bool,
    /// The headlights.
    pub headlights: bool,
}

/// One car of the plan.
#[derive(Clone, Debug, Serialize)]
pub struct VehicleSpec {
    /// Its VIN.
    pub vin: String,
    /// Its simulation seed (sensor noise, ECU serials, security seeds).
    pub seed: u64,
    /// The software each ECU left the factory with, where not 1.0.0.
    pub factory: Vec<(String, String)>,
    /// Whether its cruise ECU runs the faulty release.
    pub cruise_faulty: bool,
    /// Its drives, in order.
    pub drives: Vec<Drive>,
    /// Whether its driver agrees to updates.
    pub consents: bool,
    /// Its own broker password (its login is its VIN), when the broker has one for it;
    /// none: the fleet configuration's login. Never written to the truth.
    #[serde(skip)]
    pub broker_password: Option<String>,
}

fn pick(rng: &mut ChaCha8Rng, releases: &[(Version, f64)]) -> Version {
    let mut x: f64 = rng.random();
    for (version, share) in releases {
        if x < *share {
            return *version;
        }
        x -= share;
    }
    releases.last().map_or(Version::new(1, 0, 0), |r| r.0)
}

/// The fleet of a plan (deterministic: the same plan, the same cars).
pub fn plan(plan: &FleetPlan) -> Vec<VehicleSpec> {
    let mut rng = ChaCha8Rng::seed_from_u64(plan.seed);
    (0..plan.vehicles)
        .map(|i| {
            // JA3 (the report's Mitsubishi), AP47H, check digit, 2000 (Y), plant F, serial.
            let serial = (u64::from(plan.first_serial) + i as u64) % 1_000_000;
            let text = format!("JA3AP47H0YF{serial:06}");
            let vin = Vin::with_check_digit(&text).map_or(text, |v| v.to_string());
            let cruise = pick(&mut rng, &CRUISE_RELEASES);
            let mut factory = Vec::new();
            for (ecu, version) in [
                ("cruise", cruise),
                ("abs", pick(&mut rng, &ABS_RELEASES)),
                ("engine", pick(&mut rng, &ENGINE_RELEASES)),
            ] {
                if version != Version::new(1, 0, 0) {
                    factory.push((ecu.to_string(), version.to_string()));
                }
            }
            let drives = (0..plan.drives)
                .map(|_| {
                    let cruise = rng.random_bool(CRUISE_DRIVE_SHARE);
                    Drive {
                        target_kmh: rng.random_range(70.0..110.0_f64).round(),
                        cruise,
                        hold_s: if cruise {
                            rng.random_range(MIN_CRUISE_S..35.0_f64).round()
                        } else {
                            rng.random_range(10.0..25.0_f64).round()
                        },
                        economy: rng.random_bool(0.5),
                        headlights: rng.random_bool(0.3),
                    }
                })
                // Drawn as ever (the same seed, the same fleet), then lengthened: about
                // half a minute goes to starting, accelerating, braking and standing.
                .map(|mut drive: Drive| {
                    if let Some(minutes) = plan.drive_minutes {
                        drive.hold_s = (minutes * 60.0 - DRIVE_OVERHEAD_S).max(drive.hold_s);
                    }
                    drive
                })
                .collect();
            VehicleSpec {
                vin,
                seed: rng.random(),
                factory,
                cruise_faulty: cruise == FAULTY_CRUISE,
                drives,
                consents: !rng.random_bool(plan.decline_share.clamp(0.0, 1.0)),
                broker_password: None,
            }
        })
        .collect()
}

impl VehicleSpec {
    /// The car's scenario: its VIN, seed and factory software; no timeline (its driver
    /// takes the wheel), standing in neutral with the engine idling.
    pub fn scenario(&self) -> Result<Scenario, String> {
        let factory: String = self
            .factory
            .iter()
            .map(|(ecu, version)| format!("{ecu} = \"{version}\"\n"))
            .collect();
        let text = format!(
            "name = \"fleet-{vin}\"\n\
             description = \"A car of autoplug fleet simulate\"\n\
             duration_s = {duration}\n\
             seed = {seed}\n\
             vin = \"{vin}\"\n\
             [initial]\nspeed_kmh = 0.0\ngear = \"N\"\n\
             [ecus]\ncruise = \"{cruise}\"\n\
             [factory]\n{factory}",
            vin = self.vin,
            seed = self.seed,
            duration = CAR_LIFE_S,
            cruise = if self.cruise_faulty {
                "faulty"
            } else {
                "correct"
            },
        );
        Scenario::parse(&text, &format!("the scenario of {}", self.vin)).map_err(|e| e.to_string())
    }
}

/// What happened on a drive, as the simulation knows it (not as the gateway judged it).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DriveTruth {
    /// Time with cruise control engaged, s.
    pub cruise_engaged_s: f64,
    /// Whether the cruise ECU ran the faulty software during it.
    pub cruise_software_faulty: bool,
    /// The cruise software's version during it.
    pub cruise_version: String,
    /// Distance, m.
    pub distance_m: f64,
    /// Simulated time of the drive, s.
    pub duration_s: f64,
}

impl DriveTruth {
    /// Whether the drive showed the faulty cruise (engaged long enough to judge).
    pub fn showed_faulty_cruise(&self) -> bool {
        self.cruise_software_faulty && self.cruise_engaged_s >= MIN_CRUISE_S - 1.0
    }
}

/// A car after an order.
#[derive(Clone, Debug, Serialize)]
pub struct VehicleStatus {
    /// Its VIN.
    pub vin: String,
    /// Its drives so far.
    pub drives: Vec<DriveTruth>,
    /// The cruise software it runs now (the simulation's truth).
    pub cruise_version: String,
    /// Whether that software is the faulty one.
    pub cruise_faulty: bool,
    /// Its reports on campaigns, latest few.
    pub campaign_reports: Vec<CampaignReport>,
    /// Its gateway's latest fleet events (instructions refused, checks, reports).
    pub events: Vec<String>,
    /// Whether its MQTT connection is open.
    pub online: bool,
    /// Reports it still holds for the broker.
    pub waiting_reports: usize,
    /// Simulated time so far, s.
    pub sim_s: f64,
    /// What went wrong, if anything.
    pub error: Option<String>,
}

/// An order to the whole fleet.
#[derive(Clone, Debug)]
pub enum Order {
    /// Every car drives its next planned drive.
    Drive,
    /// Every car stays parked, answering updates the fleet offers, until the flag is set
    /// (then each finishes what it started).
    Park(Arc<AtomicBool>),
    /// These cars lose their connection (their sessions stay at the broker).
    Offline(Vec<String>),
    /// These cars connect again.
    Online(Vec<String>),
}

/// One car.
pub struct SimVehicle {
    spec: VehicleSpec,
    source: Transmitting<VirtualCarSource>,
    pipeline: Pipeline,
    watch: Watch<'static>,
    awake: bool,
    next_drive: usize,
    truths: Vec<DriveTruth>,
    error: Option<String>,
    /// Bus time the ignition went on for an update.
    woke_at_us: Option<u64>,
}

impl SimVehicle {
    /// The car of `spec`, its gateway reporting through `fleet`, connections on `runtime`.
    pub fn new(
        spec: VehicleSpec,
        mut fleet: FleetConfig,
        runtime: tokio::runtime::Handle,
    ) -> Result<Self, String> {
        if let Some(password) = &spec.broker_password {
            fleet.broker.username = Some(spec.vin.clone());
            fleet.broker.password = Some(password.clone());
        }
        let scenario = spec.scenario()?;
        let mut car = VirtualCar::new(&scenario);
        car.take_wheel();
        let outbox: Outbox = Rc::new(RefCell::new(VecDeque::new()));
        let source = Transmitting::new(VirtualCarSource::new(car), Rc::clone(&outbox));
        let mut watch = Watch::new(None);
        watch.tester = Some(BusTester::new(
            &ECUS,
            TesterConfig::DEFAULT,
            outbox,
            DTC_INTERVAL_US,
        ));
        watch.fleet = Some(FleetLink::new(fleet, runtime));
        let mut vehicle = Self {
            spec,
            source,
            pipeline: Pipeline::new(Strictness::Strict),
            watch,
            awake: true,
            next_drive: 0,
            truths: Vec::new(),
            error: None,
            woke_at_us: None,
        };
        // The gateway reads the identification (and connects) before the first drive;
        // then the car is parked with the ignition off.
        vehicle.run_for(3_000_000, |_| {});
        vehicle.ignition(false);
        vehicle.run_for(IGNITION_OFF_US, |_| {});
        Ok(vehicle)
    }

    fn car(&mut self) -> &mut VirtualCar {
        self.source.inner_mut().car_mut()
    }

    fn ignition(&mut self, on: bool) {
        let car = self.car();
        for node in ECUS {
            car.set_silenced(node, !on);
        }
        self.awake = on;
    }

    /// Runs the car and its gateway for `us` of simulated time, `each` called between
    /// polls with the car (the driver's hands).
    fn run_for(&mut self, us: u64, mut each: impl FnMut(&mut VirtualCar)) {
        let until = self.car().time_us() + us;
        let Self {
            source,
            pipeline,
            watch,
            error,
            ..
        } = self;
        // The driver's hands move between short runs of the pipeline (a few ms of bus).
        loop {
            let car = source.inner_mut().car_mut();
            if car.time_us() >= until {
                break;
            }
            if car.finished() {
                error.get_or_insert(format!(
                    "the car has lived its {CAR_LIFE_S} s of simulated time"
                ));
                break;
            }
            each(car);
            let mut polls = 0;
            let result = pipeline.run(source, &mut [watch], &mut || {
                polls += 1;
                polls > POLLS_PER_RUN
            });
            if let Err(e) = result {
                error.get_or_insert(e.to_string());
                break;
            }
        }
    }

    fn fleet(&mut self) -> &mut FleetLink {
        self.watch
            .fleet
            .as_mut()
            .expect("every simulated car has a fleet link")
    }

    /// The driver answers an offer at once (install when parked, or not).
    fn answer_offer(&mut self) {
        let consents = self.spec.consents;
        let fleet = self.fleet();
        if let Some(campaign) = fleet.offer().map(|o| o.campaign) {
            let _ = fleet.consent(campaign, consents);
        }
    }

    fn installing(&mut self) -> bool {
        self.fleet().activity().is_some_and(|(_, step)| {
            matches!(
                step,
                "waiting for the car to stand still" | "flashing" | "checking the new version"
            )
        })
    }

    /// The next planned drive (a drive past the plan repeats the last one).
    pub fn drive(&mut self) {
        let Some(drive) = self
            .spec
            .drives
            .get(self.next_drive)
            .or(self.spec.drives.last())
            .cloned()
        else {
            return;
        };
        self.next_drive += 1;
        let start_us = self.car().time_us();
        let start_m = self.car().vehicle().distance_m;
        self.ignition(true);
        let mut engaged_us = 0u64;
        let mut faulty = false;
        let mut version = String::new();
        // Phases: warm up, accelerate, hold (cruise or foot), brake, stand.
        let mut phase = 0;
        let mut phase_start = start_us;
        let mut last_t = start_us;
        let mut pressed = false;
        let held = |accelerator: f64, brake: f64| HeldControls {
            accelerator,
            brake,
            steering_deg: 0.0,
            headlights: drive.headlights,
            economy_mode: drive.economy,
            manual_mode: false,
            set_temp_f: 72.0,
        };
        loop {
            let mut next = phase;
            self.answer_offer();
            let installing = self.installing();
            self.run_for(SLICE_US / 10, |car| {
                let t = car.time_us();
                let speed = f64::from(car.vehicle().speed_kmh());
                if car.cruise_status().is_some_and(|c| c.engaged) {
                    engaged_us += t - last_t;
                }
                last_t = t;
                let in_phase_s = (t - phase_start) as f64 * 1e-6;
                let wheel = car.take_wheel();
                let _ = match phase {
                    0 => wheel.hold(held(0.0, 20.0)),
                    1 => wheel.hold(held(60.0, 0.0)),
                    2 if drive.cruise => wheel.hold(held(0.0, 0.0)),
                    2 => wheel.hold(held(
                        (20.0 + 8.0 * (drive.target_kmh - speed)).clamp(0.0, 100.0),
                        0.0,
                    )),
                    3 => wheel.hold(held(0.0, 35.0)),
                    _ => wheel.hold(held(0.0, 30.0)),
                };
                next = match phase {
                    0 if in_phase_s >= 2.0 => 1,
                    1 if speed >= drive.target_kmh - 2.0 || in_phase_s > 60.0 => 2,
                    // Cruise goes on once the foot is off the accelerator (a pressed pedal
                    // cancels it).
                    2 if drive.cruise && !pressed && in_phase_s >= 0.5 => {
                        wheel.press(Button::CruiseOn);
                        pressed = true;
                        2
                    }
                    2 if in_phase_s >= drive.hold_s => {
                        if drive.cruise {
                            wheel.press(Button::CruiseOff);
                        }
                        3
                    }
                    3 if speed < 0.5 => 4,
                    // Standing: the ignition goes off, unless an update is being installed.
                    4 if in_phase_s >= 3.0 && !installing => 5,
                    other => other,
                };
            });
            let car = self.car();
            if let Some(diag) = car.ecu_diag(Node::Cruise) {
                faulty |= diag.installed().variant == SoftwareVariant::Faulty;
                version = diag.installed().version.to_string();
            }
            if next != phase {
                phase = next;
                phase_start = self.car().time_us();
            }
            if phase == 5 || self.error.is_some() {
                break;
            }
        }
        let end_us = self.car().time_us();
        let distance_m = self.car().vehicle().distance_m - start_m;
        self.ignition(false);
        self.run_for(IGNITION_OFF_US, |_| {});
        self.truths.push(DriveTruth {
            cruise_engaged_s: engaged_us as f64 * 1e-6,
            cruise_software_faulty: faulty,
            cruise_version: version,
            distance_m,
            duration_s: (end_us - start_us) as f64 * 1e-6,
        });
    }

    /// One turn of a parked car: the gateway's link is polled; an offer is answered, and
    /// with consent the ignition goes on until the update is installed (or refused, or
    /// failed). Returns whether the car has work under way.
    pub fn park_turn(&mut self) -> bool {
        if !self.awake {
            // The gateway stays awake on the link while the ECUs sleep.
            self.poll_gateway();
            self.answer_offer();
            if !self.installing() {
                return false;
            }
            self.ignition(true);
            self.woke_at_us = Some(self.car().time_us());
        }
        self.run_for(SLICE_US, |car| {
            let wheel = car.take_wheel();
            let held = *wheel.held();
            let _ = wheel.hold(HeldControls {
                accelerator: 0.0,
                brake: 30.0,
                ..held
            });
        });
        let awake_s = self
            .woke_at_us
            .map_or(0.0, |t| (self.car().time_us() - t) as f64 * 1e-6);
        if !self.installing() && awake_s > 1.0 || awake_s > 600.0 || self.error.is_some() {
            self.ignition(false);
            self.run_for(IGNITION_OFF_US, |_| {});
            self.woke_at_us = None;
            return false;
        }
        true
    }

    /// The gateway's idle call with the ECUs asleep: the link is polled.
    fn poll_gateway(&mut self) {
        use autoplug_gateway::Observer;
        let Self {
            pipeline, watch, ..
        } = self;
        watch.on_idle(pipeline.state());
    }

    /// Closes or opens its connection (its session stays at the broker).
    pub fn set_online(&mut self, online: bool) {
        self.fleet().set_online(online);
    }

    /// Where it stands.
    pub fn status(&mut self) -> VehicleStatus {
        let (cruise_version, cruise_faulty) = self
            .car()
            .ecu_diag(Node::Cruise)
            .map(|d| {
                (
                    d.installed().version.to_string(),
                    d.installed().variant == SoftwareVariant::Faulty,
                )
            })
            .unwrap_or_default();
        let sim_s = self.car().time_us() as f64 * 1e-6;
        let (vin, drives) = (self.spec.vin.clone(), self.truths.clone());
        let fleet = self.fleet();
        VehicleStatus {
            vin,
            drives,
            cruise_version,
            cruise_faulty,
            campaign_reports: fleet.campaign_reports(),
            events: fleet.events().cloned().collect(),
            online: fleet.online(),
            waiting_reports: fleet.waiting_reports(),
            sim_s,
            error: self.error.clone(),
        }
    }

    /// Sends what waits and disconnects.
    pub fn close(mut self, timeout: Duration) {
        if let Some(fleet) = self.watch.fleet.take() {
            fleet.close(timeout);
        }
    }
}

/// The fleet: worker threads, each with its share of the cars.
pub struct SimFleet {
    workers: Vec<(mpsc::Sender<Order>, mpsc::Receiver<Vec<VehicleStatus>>)>,
    handles: Vec<JoinHandle<()>>,
}

impl SimFleet {
    /// Builds the cars of `specs` on `threads` workers (each reads its identification and
    /// connects); returns once every car is parked, with their first status.
    pub fn start(
        specs: Vec<VehicleSpec>,
        fleet: FleetConfig,
        runtime: tokio::runtime::Handle,
        threads: usize,
    ) -> Result<(Self, Vec<VehicleStatus>), String> {
        let threads = threads.clamp(1, specs.len().max(1));
        let mut shares: Vec<Vec<VehicleSpec>> = vec![Vec::new(); threads];
        for (i, spec) in specs.into_iter().enumerate() {
            shares[i % threads].push(spec);
        }
        let mut workers = Vec::new();
        let mut handles = Vec::new();
        for share in shares {
            let (order_tx, order_rx) = mpsc::channel::<Order>();
            let (status_tx, status_rx) = mpsc::channel::<Vec<VehicleStatus>>();
            let fleet = fleet.clone();
            let runtime = runtime.clone();
            handles.push(std::thread::spawn(move || {
                worker(share, fleet, runtime, order_rx, status_tx)
            }));
            workers.push((order_tx, status_rx));
        }
        let mut fleet = Self { workers, handles };
        let first = fleet.collect()?;
        Ok((fleet, first))
    }

    fn collect(&mut self) -> Result<Vec<VehicleStatus>, String> {
        let mut all = Vec::new();
        for (_, rx) in &self.workers {
            all.extend(
                rx.recv()
                    .map_err(|_| "a worker of the simulation stopped".to_string())?,
            );
        }
        all.sort_by(|a, b| a.vin.cmp(&b.vin));
        Ok(all)
    }

    /// Gives every car `order`; returns every car's status once all are done.
    pub fn order(&mut self, order: Order) -> Result<Vec<VehicleStatus>, String> {
        for (tx, _) in &self.workers {
            tx.send(order.clone())
                .map_err(|_| "a worker of the simulation stopped".to_string())?;
        }
        self.collect()
    }

    /// Stops the workers (each car sends what waits and disconnects).
    pub fn finish(self) {
        drop(self.workers);
        for handle in self.handles {
            let _ = handle.join();
        }
    }
}

fn worker(
    specs: Vec<VehicleSpec>,
    fleet: FleetConfig,
    runtime: tokio::runtime::Handle,
    orders: mpsc::Receiver<Order>,
    statuses: mpsc::Sender<Vec<VehicleStatus>>,
) {
    let mut cars = Vec::new();
    let mut failed = Vec::new();
    for spec in specs {
        let vin = spec.vin.clone();
        match SimVehicle::new(spec, fleet.clone(), runtime.clone()) {
            Ok(car) => cars.push(car),
            Err(e) => failed.push(VehicleStatus {
                vin,
                drives: Vec::new(),
                cruise_version: String::new(),
                cruise_faulty: false,
                campaign_reports: Vec::new(),
                events: Vec::new(),
                online: false,
                waiting_reports: 0,
                sim_s: 0.0,
                error: Some(e),
            }),
        }
    }
    let report = |cars: &mut Vec<SimVehicle>| {
        let mut all: Vec<VehicleStatus> = cars.iter_mut().map(|c| c.status()).collect();
        all.extend(failed.iter().cloned());
        all
    };
    if statuses.send(report(&mut cars)).is_err() {
        return;
    }
    while let Ok(order) = orders.recv() {
        match order {
            Order::Drive => cars.iter_mut().for_each(|c| c.drive()),
            Order::Park(done) => loop {
                let asked_to_stop = done.load(Ordering::SeqCst);
                let mut busy = false;
                for car in &mut cars {
                    busy |= car.park_turn();
                }
                if asked_to_stop && !busy {
                    break;
                }
                if !busy {
                    std::thread::sleep(Duration::from_millis(2));
                }
            },
            Order::Offline(vins) | Order::Online(vins) if vins.is_empty() => {}
            Order::Offline(vins) => cars
                .iter_mut()
                .filter(|c| vins.contains(&c.spec.vin))
                .for_each(|c| c.set_online(false)),
            Order::Online(vins) => cars
                .iter_mut()
                .filter(|c| vins.contains(&c.spec.vin))
                .for_each(|c| c.set_online(true)),
        }
        if statuses.send(report(&mut cars)).is_err() {
            break;
        }
    }
    let started = Instant::now();
    for car in cars {
        let left = Duration::from_secs(5).saturating_sub(started.elapsed());
        car.close(left.max(Duration::from_millis(100)));
    }
}
