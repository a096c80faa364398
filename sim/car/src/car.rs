//! The virtual car: the vehicle model, the bit-timed bus and the nine ECUs' logic, wired as
//! on the bench. Each ECU reads its sensors from the model (or the driver's controls), runs
//! its control step at its own period, and talks to the others only through CAN frames on
//! the bus; its actuator commands drive the model.
//!
//! Time advances in 1 ms ticks of simulated time. The ECUs are not synchronised: each has
//! a fixed phase offset, as independent boards would, which also spreads the bus traffic.

use crate::diag::VirtualDiag;
use crate::driver::{CarOnRoad, DriverControls, ManualDriver, RoadDriver, Timeline};
use crate::firmware::{self, FirmwareChoice, FirmwareLogLine, FirmwareStop};
use crate::scenario::FRICTION_RANGE;
use crate::scenario::{Activation, Event, GearName, Scenario, Software};
use crate::track::{self, OnTrack};
use crate::wiring::{Bench, Wiring};
use autoplug_can::{AbsMsg, CanMessage, CruiseAccelMsg, Frame, Gear as CanGear, Node, TracMsg};
use autoplug_ecu::{Dtcs, EcuLogic, Instant};
use autoplug_image::SoftwareVariant;
use autoplug_mcu::mcu::Mcu;
use autoplug_mcu::rtt::RttLog;
use autoplug_scaling::units::{celsius_to_fahrenheit, fahrenheit_to_celsius};
use autoplug_vehicle::{
    Actuators as VehicleActuators, Environment, Gear as VehicleGear, InitialState, Vehicle,
    VehicleParams, VehicleState,
};
use autoplug_virtual_bus::{AcceptanceFilter, BusConfig, NodeId, Outcome, VirtualBus};

/// Simulated time per tick.
pub const TICK_US: u64 = 1_000;

/// How fast the simulator's own hand turns the steering wheel at most, °/s: a quick human
/// hand. Pure pursuit asks for the angle the road needs at once; in a spin or after a
/// jump that would turn the wheel faster than any hand, and the gateway (which knows only
/// the bus) would rightly judge the steering ECU faulty for what the simulator did. A
/// person's own input is not limited: the gateway's routine is there to judge it.
pub const HAND_RATE_DEG_S: f64 = 800.0;

/// The name of the bus node through which outside tools (socketcand clients, a tester in
/// the process) send.
pub const EXTERNAL_SENDER: &str = "External";

/// A frame that was on the bus, for the log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoggedFrame {
    /// When it was received (end of frame), µs.
    pub t_us: u64,
    /// The frame.
    pub frame: Frame,
    /// The sender: an ECU, or `None` for the external node (a socketcand client or a
    /// tester). One byte rather than a name: a drive's log holds a frame per millisecond.
    pub sender: Option<Node>,
}

impl LoggedFrame {
    /// The sender's DBC name, or [`EXTERNAL_SENDER`].
    pub fn sender_name(&self) -> &'static str {
        self.sender.map_or(EXTERNAL_SENDER, |n| n.name())
    }
}

/// One ECU on the bus: its logic, and its diagnostic half (UDS, flash, bootloader); or,
/// when it runs as firmware on an emulated MCU, the outputs its board's pins show.
struct Slot<E: EcuLogic> {
    /// Runs as its firmware (the logic and diagnostic half here are then unused: the MCU
    /// has its own, and its bus node is the MCU's).
    emulated: bool,
    ecu: E,
    diag: VirtualDiag,
    node: NodeId,
    phase_us: u64,
    next_step_us: u64,
    outputs: Option<E::Actuators>,
    /// Steps run and frames sent since the application started: its self-test.
    steps_since_boot: u32,
    sent_since_boot: u32,
    resets: u32,
}

impl<E: Wiring> Slot<E>
where
    E::Actuators: Copy,
{
    /// The ECU on host logic, attached to the bus; or, with `emulated_node`, the slot of
    /// an ECU whose MCU is attached as that node.
    fn new(
        variant: SoftwareVariant,
        scenario: &Scenario,
        bus: &mut VirtualBus,
        phase_us: u64,
        emulated_node: Option<NodeId>,
    ) -> Self {
        let node = emulated_node.unwrap_or_else(|| {
            let mut ids = E::NODE.received_ids().to_vec();
            ids.extend(VirtualDiag::received_ids(E::NODE));
            ids.sort_unstable();
            ids.dedup();
            bus.attach(E::NODE.name(), AcceptanceFilter::ids(&ids))
        });
        let diag = VirtualDiag::new(
            E::NODE,
            variant,
            scenario.factory_version(E::NODE),
            scenario.vin(),
            scenario.seed,
        );
        let ecu = E::make(diag.installed().variant, Instant::ZERO);
        Self {
            emulated: emulated_node.is_some(),
            ecu,
            diag,
            node,
            phase_us,
            next_step_us: phase_us % E::STEP_PERIOD_US,
            outputs: None,
            steps_since_boot: 0,
            sent_since_boot: 0,
            resets: 0,
        }
    }

    fn deliver(&mut self, bus: &mut VirtualBus) {
        if self.emulated {
            return; // through its bxCAN, as the bus runs
        }
        while let Some(delivered) = bus.recv(self.node) {
            let t_us = delivered.t_ns / 1000;
            // A stalled core (flash busy) loses what its receive FIFO cannot hold.
            if !self.diag.admit(t_us) {
                continue;
            }
            let dtcs = self.ecu.dtcs_mut();
            if self.diag.on_frame(t_us, &delivered.frame, dtcs) {
                continue;
            }
            if self.diag.normal_rx_enabled() {
                self.ecu
                    .on_frame(Instant::from_micros(t_us), &delivered.frame);
            }
        }
    }

    fn step_if_due(
        &mut self,
        t_us: u64,
        sensors: impl FnOnce() -> E::Sensors,
        firmware: &mut firmware::Firmware,
    ) {
        if self.emulated {
            // The board's inputs follow the model; the firmware samples them when it will.
            if let Some(mcu) = firmware.mcu(E::NODE) {
                E::drive(&sensors(), &mut Bench::new(mcu));
            }
            return;
        }
        // A stalled core runs no step; the ticker catches up afterwards, one step per tick.
        // A step the logic asks for at once (a frame it got) restarts the period from now,
        // as the firmware's loop resets its ticker.
        let requested = self.ecu.step_requested();
        if (t_us >= self.next_step_us || requested) && !self.diag.stalled(t_us) {
            let outputs = self.ecu.step(Instant::from_micros(t_us), &sensors());
            self.diag.set_own_motion(self.ecu.own_sensors_show_motion());
            self.outputs = Some(outputs);
            self.next_step_us = if requested {
                t_us + E::STEP_PERIOD_US
            } else {
                self.next_step_us + E::STEP_PERIOD_US
            };
            self.steps_since_boot = self.steps_since_boot.saturating_add(1);
        }
    }

    /// An emulated ECU's outputs, as its pins show them now (at rest once its MCU stopped).
    fn read_pins(&mut self, firmware: &mut firmware::Firmware) {
        if self.emulated {
            self.outputs = firmware
                .mcu(E::NODE)
                .and_then(|mcu| E::read(&Bench::new(mcu)));
        }
    }

    fn transmit(&mut self, bus: &mut VirtualBus, t_us: u64) {
        if self.emulated || self.diag.stalled(t_us) {
            return;
        }
        let now = Instant::from_micros(t_us);
        let tx_enabled = self.diag.normal_tx_enabled();
        while let Some(frame) = self.ecu.poll_transmit(now) {
            if !tx_enabled {
                continue; // UDS 0x28: normal messages off
            }
            // A full transmit queue is counted by the bus; the ECU's next period resends.
            if bus.send(self.node, frame, t_us * 1000).is_ok() {
                self.diag.note_sent(t_us, &frame);
                self.sent_since_boot = self.sent_since_boot.saturating_add(1);
            }
        }
        // Responses to the requests handled at delivery go out first; then the stack's
        // timers and a programming slice, which stalls the core (what it produces goes
        // out once the stall is over).
        for frame in self.diag.poll_transmit(t_us) {
            let _ = bus.send(self.node, frame, t_us * 1000);
        }
        let reset = self.diag.poll(t_us, self.ecu.dtcs_mut());
        for frame in self.diag.poll_transmit(t_us) {
            let _ = bus.send(self.node, frame, t_us * 1000);
        }
        if self.steps_since_boot > 0 && self.sent_since_boot > 0 {
            self.diag.self_test_passed(t_us);
        }
        if reset {
            self.reset(t_us);
        }
    }

    /// The tester asked for a reset: the bootloader runs (starting a new image on trial
    /// or reverting one, as the boot record says), then the application starts afresh with the installed
    /// software: its logic rebuilt, RAM (DTCs included) cleared, outputs at rest.
    fn reset(&mut self, t_us: u64) {
        let boot = self.diag.boot(t_us);
        let started = self.diag.booted_at_us();
        self.ecu = E::make(boot.header.variant, Instant::from_micros(started));
        self.outputs = None;
        self.next_step_us = started + self.phase_us % E::STEP_PERIOD_US;
        self.steps_since_boot = 0;
        self.sent_since_boot = 0;
        self.resets += 1;
    }
}

/// The ECUs, one slot each, in the registry's order (the order they start in, their
/// phases a step apart): what the car does with every ECU, written once over the list.
macro_rules! ecus {
    ($(($node:ident, $name:ident, $krate:ident, $logic:ident)),* $(,)?) => {
        /// The car's ECUs.
        struct Ecus {
            $($name: Slot<autoplug_ecus::$name::$logic>,)*
        }

        impl Ecus {
            /// Every ECU on the bus: on host logic, or its board attached when `choice`
            /// runs it as firmware; each with the software the scenario gives it.
            fn build(
                scenario: &Scenario,
                choice: Option<&FirmwareChoice>,
                fw: &mut firmware::Firmware,
                bus: &mut VirtualBus,
            ) -> Result<Self, String> {
                let mut phases = (0..).map(|i| i * PHASE_SPACING_US);
                let mut loaded = match choice {
                    Some(choice) => firmware::load_all(&choice.ecus, &choice.dir, scenario.seed)?,
                    None => Vec::new(),
                };
                if let Some(choice) = choice {
                    fw.set_debugged(firmware::serve_debuggers(choice, &mut loaded)?);
                }
                $(
                    let emulated = emulate(fw, &mut loaded, Node::$node, bus);
                    let phase_us = phases.next().unwrap_or_default();
                    let software = software_of(scenario, Node::$node);
                    let $name = Slot::new(software, scenario, bus, phase_us, emulated);
                )*
                Ok(Self { $($name),* })
            }

            /// Each ECU's DTCs on host logic, and whether it is emulated.
            fn dtcs(&self) -> Vec<(Node, bool, &Dtcs)> {
                vec![$((Node::$node, self.$name.emulated, self.$name.ecu.dtcs())),*]
            }

            fn emulated(&self, node: Node) -> bool {
                match node {
                    $(Node::$node => self.$name.emulated,)*
                    _ => false,
                }
            }

            fn diag(&self, node: Node) -> Option<&VirtualDiag> {
                match node {
                    $(Node::$node => Some(&self.$name.diag),)*
                    _ => None,
                }
            }

            /// What the emulated boards' pins show, then the frames that reached each ECU.
            fn receive(&mut self, fw: &mut firmware::Firmware, bus: &mut VirtualBus) {
                $(self.$name.read_pins(fw);)*
                $(self.$name.deliver(bus);)*
            }

            /// Each ECU's control step, when due, on its own sensors.
            fn step(
                &mut self,
                t_us: u64,
                state: &VehicleState,
                controls: &DriverControls,
                fw: &mut firmware::Firmware,
            ) {
                $(self.$name.step_if_due(
                    t_us,
                    || <autoplug_ecus::$name::$logic as Wiring>::sensors(state, controls),
                    fw,
                );)*
            }

            /// Frames due now go to the ECUs' transmit queues.
            fn transmit(&mut self, bus: &mut VirtualBus, t_us: u64) {
                $(self.$name.transmit(bus, t_us);)*
            }
        }
    };
}
autoplug_ecus::for_each_ecu!(ecus);

/// The software an ECU starts with in `scenario` (the faulty software exists for cruise
/// and ABS).
fn software_of(scenario: &Scenario, node: Node) -> SoftwareVariant {
    let software = match node {
        Node::Cruise => scenario.ecus.cruise,
        Node::ABS => scenario.ecus.abs,
        _ => Software::Correct,
    };
    match software {
        Software::Correct => SoftwareVariant::Standard,
        Software::Faulty => SoftwareVariant::Faulty,
    }
}

/// Everything recorded about one moment, in physical units from the model (not the
/// quantised CAN values).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TraceRow {
    /// Time, s.
    pub t_s: f64,
    /// Position east, m.
    pub x_m: f64,
    /// Position north, m.
    pub y_m: f64,
    /// Heading, rad.
    pub heading_rad: f64,
    /// Longitudinal speed, km/h.
    pub speed_kmh: f64,
    /// Yaw rate, rad/s.
    pub yaw_rate_rad_s: f64,
    /// Reference yaw rate, rad/s.
    pub yaw_rate_ref_rad_s: f64,
    /// Wheel speeds FL, FR, RL, RR, km/h.
    pub wheel_speed_kmh: [f64; 4],
    /// Applied brake per wheel (the ABS ECU's output), %.
    pub brake: [f64; 4],
    /// ABS release per wheel, %.
    pub abs_release: [f64; 4],
    /// Driver's accelerator pedal, %.
    pub accel_pedal: f64,
    /// Driver's brake pedal, %.
    pub brake_pedal: f64,
    /// Accelerator command (pedals ECU), %.
    pub accel_cmd: f64,
    /// Brake command (pedals ECU), %.
    pub brake_cmd: f64,
    /// Steering wheel angle at the steering actuator, degrees.
    pub steering_deg: f64,
    /// Engaged gear: -1 reverse, 0 neutral, 1..6.
    pub gear: i32,
    /// Engine speed, rpm.
    pub engine_rpm: f64,
    /// Fuel in the tank, L.
    pub fuel_l: f64,
    /// Cabin temperature, °F.
    pub cabin_temp_f: f64,
    /// Cabin set temperature, °F.
    pub cabin_set_f: f64,
    /// Fan power, %.
    pub fan: f64,
    /// Cruise engaged.
    pub cruise_on: bool,
    /// Cruise set speed, km/h.
    pub cruise_set_kmh: f64,
    /// Cruise command, -100..100.
    pub cruise_cmd: f64,
    /// Rear torque split applied, N·m.
    pub torque_split_nm: f64,
    /// Headlights on.
    pub headlights: bool,
    /// Brake lights on.
    pub brake_lights: bool,
    /// ABS acting.
    pub abs_active: bool,
    /// Traction control cut, %.
    pub traction_cut: f64,
    /// Longitudinal acceleration, m/s².
    pub ax_mps2: f64,
    /// Lateral acceleration, m/s².
    pub ay_mps2: f64,
    /// Distance travelled, m.
    pub distance_m: f64,
    /// Which wheels mark the road (locked, spinning or sliding), FL FR RL RR
    /// ([`crate::world::wheel_marks`]). Not in `trace.csv`.
    pub marks: [bool; 4],
}

impl TraceRow {
    /// The sample's time, µs (the tick it was taken at).
    pub fn t_us(&self) -> u64 {
        (self.t_s * 1e6).round() as u64
    }
}

/// The running car.
pub struct VirtualCar {
    scenario: Scenario,
    vehicle: Vehicle,
    /// Road and weather as the scenario sets them (on a track: the friction of its
    /// asphalt's left and right halves); the car's own, per wheel, is the vehicle's.
    environment: Environment,
    /// The track, when the scenario names one.
    track: Option<OnTrack>,
    /// The scenario's driver when it follows the road or holds a speed.
    road_driver: RoadDriver,
    bus: VirtualBus,
    ecus: Ecus,
    external: NodeId,
    timeline: Timeline,
    /// A person driving instead of the timeline, once one took the wheel.
    manual: Option<ManualDriver>,
    /// The simulator steers the person's car along its road (the person keeps the pedals
    /// and the rest): the lateral half of the road driver, as a desk simulator offers.
    steers_along_road: bool,
    /// The angle the simulator's hand last set, and the tick it set it (see
    /// [`HAND_RATE_DEG_S`]).
    hand: Option<(u64, f64)>,
    controls: DriverControls,
    /// The bus's time (the emulated MCUs' too), µs: the scenario's time plus `start_us`.
    t_us: u64,
    /// When the scenario began on the bus's clock: after the warm-up of a car with
    /// emulated ECUs (0 for a car on host logic).
    start_us: u64,
    log: Vec<LoggedFrame>,
    node_names: Vec<Option<Node>>,
    /// Frames the external node (a tester in the process) received, when captured.
    external_rx: Option<Vec<Frame>>,
    /// Every moment the brake pedal went down, to the tick.
    brake_presses: Vec<BrakePress>,
    /// The ECUs that run as firmware on emulated MCUs.
    firmware: firmware::Firmware,
    /// What the bus last said of the emulated ECUs' internal state (what their pins do
    /// not show), for the trace.
    bus_view: BusView,
}

/// The last cruise command, ABS message and traction cut seen on the bus.
#[derive(Clone, Copy, Debug, Default)]
struct BusView {
    cruise_accel: f32,
    abs: AbsMsg,
    traction_cut: f32,
}

impl BusView {
    fn see(&mut self, frame: &Frame) {
        // A malformed frame leaves the last good value.
        match frame.id() {
            CruiseAccelMsg::ID => {
                if let Ok(m) = CruiseAccelMsg::decode_data(frame.data()) {
                    self.cruise_accel = m.cruise_accel;
                }
            }
            AbsMsg::ID => {
                let _ = self.abs.update_from_data(frame.data());
            }
            TracMsg::ID => {
                if let Ok(m) = TracMsg::decode_data(frame.data()) {
                    self.traction_cut = m.traction_cut;
                }
            }
            _ => {}
        }
    }
}

/// Attaches `node`'s board to the bus when it runs as firmware (its MCU among `loaded`).
fn emulate(
    firmware: &mut firmware::Firmware,
    loaded: &mut Vec<(Node, Mcu, Vec<RttLog>)>,
    node: Node,
    bus: &mut VirtualBus,
) -> Option<NodeId> {
    let i = loaded.iter().position(|(n, _, _)| *n == node)?;
    let (_, mcu, logs) = loaded.remove(i);
    Some(firmware.attach(bus, node, mcu, logs))
}

/// The car at the tick the driver pressed the brake pedal (from released): where a stop
/// begins. The 10 ms trace would put it up to a sample later, when the brake has already
/// taken some of the speed and the stop looks shorter than it was.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrakePress {
    /// Simulated time of the tick that saw the pedal down, µs.
    pub t_us: u64,
    /// Distance travelled then, m.
    pub distance_m: f64,
    /// Speed then, km/h.
    pub speed_kmh: f64,
    /// Heading then, rad.
    pub heading_rad: f64,
}

impl BrakePress {
    /// The car at a trace sample, as a press there would find it.
    pub fn at(row: &TraceRow) -> Self {
        Self {
            t_us: row.t_us(),
            distance_m: row.distance_m,
            speed_kmh: row.speed_kmh,
            heading_rad: row.heading_rad,
        }
    }
}

fn vehicle_gear(gear: GearName) -> VehicleGear {
    match gear {
        GearName::Reverse => VehicleGear::Reverse,
        GearName::Neutral => VehicleGear::Neutral,
        GearName::Forward(n) => VehicleGear::Forward(n),
    }
}

/// The model's engaged gear as the gear lines report it.
pub fn can_gear(gear: VehicleGear) -> CanGear {
    match gear {
        VehicleGear::Reverse => CanGear::Reverse,
        VehicleGear::Neutral | VehicleGear::Forward(0) => CanGear::Neutral,
        VehicleGear::Forward(1) => CanGear::First,
        VehicleGear::Forward(2) => CanGear::Second,
        VehicleGear::Forward(3) => CanGear::Third,
        VehicleGear::Forward(4) => CanGear::Fourth,
        VehicleGear::Forward(5) => CanGear::Fifth,
        VehicleGear::Forward(_) => CanGear::Sixth,
    }
}

/// The transmission ECU's gear command as the gearbox takes it.
pub fn commanded_gear(gear: CanGear) -> VehicleGear {
    match gear {
        CanGear::Reverse => VehicleGear::Reverse,
        CanGear::Neutral => VehicleGear::Neutral,
        CanGear::First => VehicleGear::Forward(1),
        CanGear::Second => VehicleGear::Forward(2),
        CanGear::Third => VehicleGear::Forward(3),
        CanGear::Fourth => VehicleGear::Forward(4),
        CanGear::Fifth => VehicleGear::Forward(5),
        CanGear::Sixth => VehicleGear::Forward(6),
    }
}

fn gear_number(gear: VehicleGear) -> i32 {
    match gear {
        VehicleGear::Reverse => -1,
        VehicleGear::Neutral => 0,
        VehicleGear::Forward(n) => i32::from(n),
    }
}

fn environment_of(scenario: &Scenario) -> Environment {
    let road = &scenario.road;
    Environment {
        mu: [road.mu_left, road.mu_right, road.mu_left, road.mu_right],
        grade_percent: [road.grade_percent; 4],
        ambient_c: road.ambient_c,
        sun_load_w: road.sun_load_w,
    }
}

/// How long the ignition is on before the scenario begins when ECUs run as firmware: the
/// bootloader (about 40 ms on a board that has run before, reading its A/B record at the
/// reset clock of 16 MHz), the application's start (CAN1 on the bus about 25 ms later)
/// and the first steps of the 10 and 20 ms control loops. The car is held meanwhile, so
/// the longer this is, the longer a command (a gear) waits for a car that does not move.
pub const WARM_UP_US: u64 = 100_000;

/// Between the phases of the ECUs' control steps, µs: nine spread over the first 5 ms.
const PHASE_SPACING_US: u64 = 600;

impl VirtualCar {
    /// The car at the start of a scenario, every ECU on host logic.
    pub fn new(scenario: &Scenario) -> Self {
        match Self::build(scenario, None, None) {
            Ok(car) => car,
            // Only loading firmware can fail.
            Err(e) => unreachable!("{e}"),
        }
    }

    /// The car at the start of a scenario, the chosen ECUs running as their firmware on
    /// emulated STM32F446s. Fails, saying why, when an image cannot be loaded.
    pub fn with_firmware(scenario: &Scenario, choice: &FirmwareChoice) -> Result<Self, String> {
        Self::with_firmware_showing_log(scenario, choice, None)
    }

    /// The same, each line of the ECUs' defmt logs shown by `show` as the car reads it,
    /// from the first start on, and as a debugger halts an ECU (read then, as probe-rs
    /// reads RTT at a halt, while the car's thread stands still): the terminal of a
    /// real-time run. The lines are kept for [`VirtualCar::take_firmware_log`] all the same.
    pub fn with_firmware_showing_log(
        scenario: &Scenario,
        choice: &FirmwareChoice,
        show: Option<crate::firmware::LiveLogSink>,
    ) -> Result<Self, String> {
        for (node, software) in [
            (Node::Cruise, scenario.ecus.cruise),
            (Node::ABS, scenario.ecus.abs),
        ] {
            if choice.runs(node) && software == Software::Faulty {
                return Err(format!(
                    "{}: the scenario runs the faulty {} software, and an emulated ECU runs the image it is given: run it on host logic, or flash the faulty build over UDS",
                    scenario.name,
                    autoplug_can::ecu_name(node)
                ));
            }
        }
        let mut car = Self::build(scenario, Some(choice), show)?;
        car.warm_up(WARM_UP_US);
        Ok(car)
    }

    fn build(
        scenario: &Scenario,
        choice: Option<&FirmwareChoice>,
        show: Option<crate::firmware::LiveLogSink>,
    ) -> Result<Self, String> {
        let environment = environment_of(scenario);
        let start = scenario.track.as_ref().map_or(
            autoplug_road::Pose {
                x_m: 0.0,
                y_m: 0.0,
                heading_rad: 0.0,
            },
            |t| track::start_pose(&t.road, scenario.road.start_m, scenario.road.lane_m),
        );
        let initial = InitialState {
            speed_kmh: scenario.initial.speed_kmh,
            gear: vehicle_gear(scenario.initial.gear),
            fuel_l: scenario.initial.fuel_l,
            cabin_temp_c: f64::from(fahrenheit_to_celsius(scenario.initial.cabin_temp_f as f32)),
            x_m: start.x_m,
            y_m: start.y_m,
            heading_rad: start.heading_rad,
        };
        let mut vehicle = Vehicle::new(Self::vehicle_params(), environment, initial, scenario.seed);
        let mut on_track = scenario
            .track
            .as_ref()
            .map(|t| OnTrack::new(t.clone(), &vehicle));
        if let Some(on_track) = &mut on_track {
            let env = on_track.update(&vehicle, &environment);
            vehicle.set_environment(env);
        }
        let mut bus = VirtualBus::new(BusConfig {
            seed: scenario.seed,
            // Drained every tick: a 1 ms tick holds at most ~10 frames.
            event_log_capacity: 1024,
            ..BusConfig::default()
        });
        let mut fw = firmware::Firmware::new();
        if let Some(show) = show {
            fw.show_log(show);
        }
        let ecus = Ecus::build(scenario, choice, &mut fw, &mut bus)?;
        // The gateway listens to everything (and acknowledges), like the middleware on
        // the bench; tools attached over socketcand send through this node too.
        let external = bus.attach(EXTERNAL_SENDER, AcceptanceFilter::All);
        let node_names = bus.nodes().map(|n| node_of(bus.node_name(n))).collect();
        let timeline = Timeline::new(scenario);
        let mut car = Self {
            scenario: scenario.clone(),
            vehicle,
            environment,
            track: on_track,
            road_driver: RoadDriver::default(),
            bus,
            ecus,
            external,
            controls: *timeline.initial_controls(),
            timeline,
            manual: None,
            steers_along_road: false,
            hand: None,
            t_us: 0,
            start_us: 0,
            log: Vec::with_capacity(1 << 16),
            node_names,
            external_rx: None,
            brake_presses: Vec::new(),
            firmware: fw,
            bus_view: BusView::default(),
        };
        // Road and fault changes at t = 0 take effect from the first tick, like any other.
        let mut at_start = Vec::new();
        car.controls = car
            .timeline
            .advance(0.0, |event| at_start.push(event.clone()));
        for event in at_start {
            car.apply_event(&event);
        }
        Ok(car)
    }

    /// The car the virtual car simulates: the Lancer Evolution VI of the 2011 report.
    pub fn vehicle_params() -> VehicleParams {
        VehicleParams::evo_vi()
    }

    /// Every press of the brake pedal so far (since the last
    /// [`take_brake_presses`](Self::take_brake_presses)), in time order.
    pub fn brake_presses(&self) -> &[BrakePress] {
        &self.brake_presses
    }

    /// Takes the presses recorded so far: a car that runs for as long as a person drives
    /// it (the dashboard) keeps none it has no use for.
    pub fn take_brake_presses(&mut self) -> Vec<BrakePress> {
        std::mem::take(&mut self.brake_presses)
    }

    /// Simulated time since the scenario began, µs.
    pub fn time_us(&self) -> u64 {
        self.t_us.saturating_sub(self.start_us)
    }

    /// The scenario being run.
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// The vehicle's state.
    pub fn vehicle(&self) -> &VehicleState {
        self.vehicle.state()
    }

    /// The driver's controls now.
    pub fn controls(&self) -> &DriverControls {
        &self.controls
    }

    /// A person takes the wheel (the dashboard's Drive view): from the next tick the
    /// controls are theirs, starting from where the timeline left them, and the timeline
    /// only changes the road and the faults. Returns the driver to move the controls.
    pub fn take_wheel(&mut self) -> &mut ManualDriver {
        let controls = self.controls;
        self.manual
            .get_or_insert_with(|| ManualDriver::taking_over(&controls))
    }

    /// The person at the wheel, if one took it.
    pub fn manual_driver(&self) -> Option<&ManualDriver> {
        self.manual.as_ref()
    }

    /// The simulator steers the person's car along its track (`true`: the steering the
    /// person holds is ignored until it is turned off), as a desk simulator's lane keeping
    /// does for a person on the pedals. Refused on the endless plane: there is no road.
    pub fn set_steering_along_road(&mut self, on: bool) -> Result<(), String> {
        if on && self.track.is_none() {
            return Err("the car has no road to steer along (its scenario names no track)".into());
        }
        self.steers_along_road = on;
        Ok(())
    }

    /// Whether the simulator steers the person's car along its track.
    pub fn steers_along_road(&self) -> bool {
        self.steers_along_road
    }

    /// Changes the road's friction (the simulator's track, not a driver control): left
    /// and right wheels, [`FRICTION_RANGE`]. Refused outside it.
    pub fn set_friction(&mut self, mu_left: f64, mu_right: f64) -> Result<(), String> {
        for mu in [mu_left, mu_right] {
            if !(FRICTION_RANGE.contains(&mu)) {
                return Err(format!(
                    "friction {mu} is outside {}..={}",
                    FRICTION_RANGE.start(),
                    FRICTION_RANGE.end()
                ));
            }
        }
        let mut env = self.environment;
        env.mu = [mu_left, mu_right, mu_left, mu_right];
        self.set_environment(env);
        Ok(())
    }

    /// The scenario's road and weather become `env` (on a track, the surfaces under the
    /// wheels are found again at the next tick).
    fn set_environment(&mut self, env: Environment) {
        if env != self.environment {
            self.environment = env;
            if self.track.is_none() {
                self.vehicle.set_environment(env);
            }
        }
    }

    /// Speed below which the car counts as standing for [`VirtualCar::back_to_start`], m/s.
    pub const STANDING_MPS: f64 = 0.5;

    /// Takes the standing car back to where the scenario started it (on its track: the
    /// start line), as a person resetting a driving simulator does. Refused while it
    /// moves.
    pub fn back_to_start(&mut self) -> Result<(), String> {
        let s = self.vehicle.state();
        if s.speed_mps.abs() > Self::STANDING_MPS {
            return Err(format!(
                "the car moves ({:.1} km/h): stop it first",
                s.speed_mps.abs() * 3.6
            ));
        }
        self.put_at_start();
        Ok(())
    }

    /// Puts the car, standing, where the scenario started it.
    fn put_at_start(&mut self) {
        let start = self.scenario.track.as_ref().map_or(
            autoplug_road::Pose {
                x_m: 0.0,
                y_m: 0.0,
                heading_rad: 0.0,
            },
            |t| {
                track::start_pose(
                    &t.road,
                    self.scenario.road.start_m,
                    self.scenario.road.lane_m,
                )
            },
        );
        self.vehicle.place(start.x_m, start.y_m, start.heading_rad);
        if let Some(on_track) = &mut self.track {
            *on_track = OnTrack::new(on_track.track().clone(), &self.vehicle);
        }
    }

    /// The car's track and where on it the car is; `None` on the endless plane.
    pub fn track(&self) -> Option<&OnTrack> {
        self.track.as_ref()
    }

    /// The model's road and weather now: on a track, the surface under each wheel.
    pub fn wheel_environment(&self) -> &Environment {
        self.vehicle.environment()
    }

    /// The road's friction now: left and right wheels (on a track: its asphalt's halves).
    pub fn friction(&self) -> (f64, f64) {
        (self.environment.mu[0], self.environment.mu[1])
    }

    /// The bus, for statistics.
    pub fn bus(&self) -> &VirtualBus {
        &self.bus
    }

    /// Frames logged so far.
    pub fn log(&self) -> &[LoggedFrame] {
        &self.log
    }

    /// Takes the frames logged so far (for streaming them to a file or a client).
    pub fn take_log(&mut self) -> Vec<LoggedFrame> {
        std::mem::take(&mut self.log)
    }

    /// [`VirtualCar::take_log`] into `frames` (cleared first): the two buffers swap, so a
    /// caller draining the log every tick allocates nothing once both have grown.
    pub fn swap_log(&mut self, frames: &mut Vec<LoggedFrame>) {
        frames.clear();
        std::mem::swap(&mut self.log, frames);
    }

    /// The cruise ECU's last decision (host logic only: an emulated ECU's state is in its
    /// MCU, and reaches the world through its pins, the bus and UDS).
    pub fn cruise_status(&self) -> Option<autoplug_ecus::cruise::Status> {
        let slot = &self.ecus.cruise;
        (!slot.emulated).then(|| slot.ecu.status())
    }

    /// The ABS ECU's last decision (host logic only).
    pub fn abs_status(&self) -> Option<autoplug_ecus::abs::Status> {
        let slot = &self.ecus.abs;
        (!slot.emulated).then(|| slot.ecu.status())
    }

    /// The transmission ECU's state (host logic only).
    pub fn trans_status(&self) -> Option<autoplug_ecus::trans::Status> {
        let slot = &self.ecus.trans;
        (!slot.emulated).then(|| slot.ecu.status())
    }

    /// The differential ECU's state (host logic only).
    pub fn diff_status(&self) -> Option<autoplug_ecus::diff::Status> {
        let slot = &self.ecus.diff;
        (!slot.emulated).then(|| slot.ecu.status())
    }

    /// The DTCs of the ECUs on host logic, by node in the DBC's order (an emulated ECU
    /// keeps its own, read over UDS).
    pub fn dtcs(&self) -> Vec<(Node, &Dtcs)> {
        let mut dtcs: Vec<(Node, &Dtcs)> = self
            .ecus
            .dtcs()
            .into_iter()
            .filter(|(_, emulated, _)| !emulated)
            .map(|(node, _, dtcs)| (node, dtcs))
            .collect();
        // In the DBC's order, whatever the order the ECUs start in.
        dtcs.sort_by_key(|(node, _)| *node);
        dtcs
    }

    /// Whether `node` runs as its firmware on an emulated MCU.
    pub fn emulated(&self, node: Node) -> bool {
        self.ecus.emulated(node)
    }

    /// The GDB server's status of `node`'s debug port, when it has one (`--gdb`).
    pub fn debug_status(&self, node: Node) -> Option<std::sync::Arc<autoplug_mcu::gdb::GdbStatus>> {
        self.firmware.debug_status(node)
    }

    /// Every GDB server's status, by ECU (`--gdb`): for whoever shows the car (the
    /// dashboard), read from any thread while the car is halted.
    pub fn debug_ports(&self) -> crate::firmware::DebugPorts {
        self.firmware.debug_ports()
    }

    /// The wall-clock time debuggers held the car halted: what a real-time pacer leaves
    /// out (the car stood still meanwhile).
    pub fn debugger_halted_for(&self) -> std::time::Duration {
        self.firmware.debugger_halted_for()
    }

    /// The emulated ECUs' defmt log lines since the last call.
    pub fn take_firmware_log(&mut self) -> Vec<FirmwareLogLine> {
        self.firmware.take_log()
    }

    /// Firmware log lines dropped because nobody took them (the car keeps 100,000).
    pub fn firmware_log_dropped(&self) -> u64 {
        self.firmware.dropped_lines()
    }

    /// The emulated ECUs that stopped (their MCU halted or locked up), with why.
    pub fn firmware_stops(&self) -> &[FirmwareStop] {
        self.firmware.stops()
    }

    /// Instructions the emulated cores have run so far.
    pub fn firmware_instructions(&self) -> u64 {
        self.firmware.instructions()
    }

    /// Puts a frame from an outside tool (socketcand client, tester) on the bus; `false`
    /// when the external node's transmit queue is full.
    ///
    /// The frame enters at the time the bus has reached (the start of the tick to come),
    /// not at the car's own time a tick later: sending then would run the bus ahead of the
    /// emulated MCUs, which would meet a millisecond of frames at once and overrun their
    /// three-deep receive FIFOs (a download's first block lost 418 of its 585 frames).
    pub fn inject(&mut self, frame: Frame) -> bool {
        let at_ns = self.bus.now_ns();
        self.bus.send(self.external, frame, at_ns).is_ok()
    }

    /// Keeps the frames the external node receives, for [`VirtualCar::take_external_rx`]
    /// (off by default: a long run would pile them up).
    pub fn capture_external_rx(&mut self, on: bool) {
        self.external_rx = on.then(Vec::new);
    }

    /// The frames the external node (a tester in the process) received since the last
    /// call, when captured.
    pub fn take_external_rx(&mut self) -> Vec<Frame> {
        self.external_rx
            .as_mut()
            .map(std::mem::take)
            .unwrap_or_default()
    }

    /// The diagnostic half of an ECU on host logic: what it runs, whether it is stalled...
    /// (`None` for an emulated ECU, whose firmware has its own.)
    pub fn ecu_diag(&self, node: Node) -> Option<&VirtualDiag> {
        if self.emulated(node) {
            return None;
        }
        self.ecus.diag(node)
    }

    /// Stops or resumes a node's transmissions (fault injection).
    pub fn set_silenced(&mut self, node: Node, silenced: bool) {
        if let Some(id) = self.node_id(node) {
            self.bus.set_silenced(id, silenced);
        }
    }

    fn node_id(&self, node: Node) -> Option<NodeId> {
        self.bus
            .nodes()
            .find(|&n| self.bus.node_name(n) == node.name())
    }

    /// Whether the scenario's time is up.
    pub fn finished(&self) -> bool {
        self.time_us() as f64 >= self.scenario.duration_s * 1e6
    }

    /// One trace row for the present moment.
    pub fn trace_row(&self) -> TraceRow {
        let s = self.vehicle.state();
        let (abs_release, abs_active, traction_cut) = match self.abs_status() {
            Some(abs) => (abs.release, abs.abs_active, abs.traction_cut),
            None => {
                // Emulated: what AbsMsg and TracMsg say.
                let a = &self.bus_view.abs;
                let release = [
                    a.abs_release_fl,
                    a.abs_release_fr,
                    a.abs_release_rl,
                    a.abs_release_rr,
                ];
                (
                    release,
                    release.iter().any(|r| *r > 0.0),
                    self.bus_view.traction_cut,
                )
            }
        };
        let cruise = self.cruise_status().unwrap_or_else(|| {
            // Emulated: the lamp, the set speed the firmware logged when it engaged, and
            // the command CruiseAccelMsg carries.
            let engaged = self.ecus.cruise.outputs.is_some_and(|o| o.engaged);
            autoplug_ecus::cruise::Status {
                engaged,
                set_speed_kmh: match self.firmware.cruise_set_speed_kmh() {
                    Some(kmh) if engaged => kmh,
                    _ => 0.0,
                },
                command: self.bus_view.cruise_accel,
            }
        });
        let pedals = self.ecus.pedals.outputs.unwrap_or_default();
        let c = &self.controls;
        TraceRow {
            t_s: self.time_us() as f64 * 1e-6,
            x_m: s.x_m,
            y_m: s.y_m,
            heading_rad: s.heading_rad,
            speed_kmh: s.speed_mps * 3.6,
            yaw_rate_rad_s: s.yaw_rate_rad_s,
            yaw_rate_ref_rad_s: s.yaw_rate_ref_rad_s,
            wheel_speed_kmh: s.wheel_speed_mps.map(|v| v * 3.6),
            brake: self.applied_brake().map(|b| b * 100.0),
            abs_release: abs_release.map(f64::from),
            accel_pedal: c.held.accelerator,
            brake_pedal: c.held.brake,
            accel_cmd: f64::from(pedals.accelerator_cmd),
            brake_cmd: f64::from(pedals.brake_cmd),
            steering_deg: self.steering_command(),
            gear: gear_number(s.gear),
            engine_rpm: s.engine_rpm,
            fuel_l: s.fuel_l,
            cabin_temp_f: f64::from(celsius_to_fahrenheit(s.cabin_temp_c as f32)),
            cabin_set_f: c.held.set_temp_f,
            fan: self.ecus.cabin.outputs.map_or(0.0, |a| f64::from(a.fan)),
            cruise_on: cruise.engaged,
            cruise_set_kmh: f64::from(cruise.set_speed_kmh),
            cruise_cmd: f64::from(cruise.command),
            torque_split_nm: s.torque_split_nm,
            headlights: s.headlights,
            brake_lights: s.brake_lights,
            abs_active,
            traction_cut: f64::from(traction_cut),
            ax_mps2: s.ax_mps2,
            ay_mps2: s.ay_mps2,
            distance_m: s.distance_m,
            marks: crate::world::wheel_marks(s, self.vehicle.params()),
        }
    }

    fn applied_brake(&self) -> [f64; 4] {
        self.ecus
            .abs
            .outputs
            .map_or([0.0; 4], |a| a.brake.map(|b| f64::from(b) / 100.0))
    }

    fn steering_command(&self) -> f64 {
        self.ecus
            .steering
            .outputs
            .map_or(0.0, |a| f64::from(a.steering_cmd_deg))
    }

    /// Advances one tick (1 ms of simulated time).
    pub fn tick(&mut self) {
        self.advance(false);
    }

    /// The ignition on before the scenario begins, for `duration_us`: the ECUs start and
    /// run (the emulated ones through their bootloader) on a car held in its initial
    /// state, with the driver's initial controls; the scenario's time 0 is the end of it. A car that
    /// starts in motion meets the scenario with its ECUs running, as the host logic does.
    fn warm_up(&mut self, duration_us: u64) {
        self.start_us = self.t_us + duration_us;
        while self.t_us < self.start_us {
            self.advance(true);
        }
        self.log.clear();
        if let Some(rx) = &mut self.external_rx {
            rx.clear();
        }
    }

    /// One tick; `held`: the warm-up, in which neither the driver nor the model moves.
    fn advance(&mut self, held: bool) {
        let t_us = self.t_us;

        if !held {
            // The driver, and the road and fault changes of the timeline.
            let scenario_us = t_us - self.start_us;
            let t_s = scenario_us as f64 * 1e-6;
            let previous_brake = self.controls.held.brake;
            let mut road_changes = Vec::new();
            self.controls = self
                .timeline
                .advance(t_s, |event| road_changes.push(event.clone()));
            match self.manual.as_mut() {
                Some(person) => {
                    self.controls = person.controls_at(t_s);
                    if self.steers_along_road {
                        self.steer_to_road();
                    }
                }
                None => self.drive_along(),
            }
            if self.controls.held.brake > 0.0 && previous_brake <= 0.0 {
                // The state is still the one at `t_us`: the model integrates below.
                let s = self.vehicle.state();
                self.brake_presses.push(BrakePress {
                    t_us: scenario_us,
                    distance_m: s.distance_m,
                    speed_kmh: s.speed_mps * 3.6,
                    heading_rad: s.heading_rad,
                });
            }
            for event in road_changes {
                self.apply_event(&event);
            }
        }

        // Frames that completed by now reach their receivers; the emulated MCUs run with
        // the bus, and their pins show what they command now.
        if self.firmware.is_empty() {
            self.bus.run_until(t_us * 1000);
        } else {
            self.firmware.run(&mut self.bus, t_us * 1000, self.start_us);
            self.firmware.poll_logs(t_us, self.start_us);
        }
        self.collect_log();
        self.ecus.receive(&mut self.firmware, &mut self.bus);
        while let Some(delivered) = self.bus.recv(self.external) {
            if let Some(rx) = &mut self.external_rx {
                rx.push(delivered.frame);
            }
        }

        // Each ECU's control step, when due, on its own sensors; then the frames due now
        // go to the ECUs' transmit queues.
        let controls = self.controls;
        self.ecus
            .step(t_us, self.vehicle.state(), &controls, &mut self.firmware);
        self.ecus.transmit(&mut self.bus, t_us);

        // The actuators drive the car for the next tick, on the surface under its wheels.
        if !held {
            if let Some(on_track) = &mut self.track {
                let env = on_track.update(&self.vehicle, &self.environment);
                if env != *self.vehicle.environment() {
                    self.vehicle.set_environment(env);
                }
            }
            let actuators = self.actuators();
            self.vehicle.step(&actuators, TICK_US as f64 * 1e-6);
        }
        self.t_us += TICK_US;
    }

    /// The scenario's driver steers along the track and works the pedals to hold its
    /// speed, when the timeline says so (the rest of the controls stay the timeline's).
    fn drive_along(&mut self) {
        let following = self.timeline.follows_road();
        let target = self.timeline.speed_target_kmh();
        if following {
            self.steer_to_road();
        }
        let s = self.vehicle.state();
        if let Some(target_kmh) = target {
            let mut target_mps = target_kmh / 3.6;
            if let (true, Some(on_track)) = (following, &self.track) {
                target_mps = target_mps.min(self.road_driver.speed_allowed_at(
                    on_track.road(),
                    on_track.rear_axle_station(),
                    s.speed_mps,
                    self.t_us,
                ));
            }
            let (accelerator, brake) =
                self.road_driver
                    .pedals(s.speed_mps, target_mps, TICK_US as f64 * 1e-6);
            self.controls.held.accelerator = accelerator;
            self.controls.held.brake = brake;
        }
    }

    /// The road driver's steering: the wheel turned to keep the car on the scenario's
    /// lane of its track (no track: the wheel stays as it is).
    fn steer_to_road(&mut self) {
        let Some(on_track) = &self.track else {
            return;
        };
        let params = self.vehicle.params();
        let car = CarOnRoad {
            rear_axle: track::rear_axle(&self.vehicle),
            station_m: on_track.rear_axle_station(),
            speed_mps: self.vehicle.state().speed_mps,
            wheelbase_m: params.chassis.wheelbase_m,
            steering_ratio: params.steering.ratio,
            understeer_rad_per_mps2: params.tyre.understeer_gradient_rad_per_mps2(),
        };
        let wanted = RoadDriver::steering_deg(on_track.road(), &car, self.scenario.road.lane_m);
        // From where the hand left the wheel last tick, else from where the wheel is.
        let from = match self.hand {
            Some((t, angle)) if t + TICK_US == self.t_us => angle,
            _ => self.controls.held.steering_deg,
        };
        let step = HAND_RATE_DEG_S * TICK_US as f64 * 1e-6;
        let angle = from + (wanted - from).clamp(-step, step);
        self.controls.held.steering_deg = angle;
        self.hand = Some((self.t_us, angle));
    }

    /// What the ECUs' outputs command the vehicle to do. Before an ECU's first step its
    /// actuator rests in its neutral position.
    fn actuators(&self) -> VehicleActuators {
        let e = &self.ecus;
        let pedals = e.pedals.outputs.unwrap_or_default();
        let console = e.console.outputs.unwrap_or_default();
        let torque_split = match self.scenario.ecus.differential {
            Activation::Enabled => e.diff.outputs.map_or(0.0, |a| f64::from(a.torque_split_nm)),
            Activation::Disabled => 0.0,
        };
        VehicleActuators {
            accelerator: f64::from(pedals.accelerator_cmd) / 100.0,
            brake: self.applied_brake(),
            steering_wheel_deg: self.steering_command(),
            gear: e
                .trans
                .outputs
                .map_or(self.vehicle.state().gear, |a| commanded_gear(a.gear_cmd)),
            torque_split_nm: torque_split,
            fan: e.cabin.outputs.map_or(0.0, |a| f64::from(a.fan) / 100.0),
            headlights: console.headlights,
            brake_lights: console.brake_lights,
        }
    }

    fn apply_event(&mut self, event: &Event) {
        let mut env = self.environment;
        if let Some(g) = event.grade_percent {
            env.grade_percent = [g; 4];
        }
        if let Some(mu) = event.mu_left {
            env.mu[0] = mu;
            env.mu[2] = mu;
        }
        if let Some(mu) = event.mu_right {
            env.mu[1] = mu;
            env.mu[3] = mu;
        }
        self.set_environment(env);
        if event.to_start {
            self.put_at_start();
        }
        if let Some(fault) = &event.fault {
            for (name, silenced) in [(&fault.silence, true), (&fault.restore, false)] {
                if let Some(node) = name
                    .as_deref()
                    .and_then(|n| Node::ALL.iter().find(|node| node.name() == n))
                {
                    self.set_silenced(*node, silenced);
                }
            }
        }
    }

    fn collect_log(&mut self) {
        for event in self.bus.drain_events() {
            if matches!(event.outcome, Outcome::Received { .. }) {
                self.bus_view.see(&event.frame);
            }
            if matches!(event.outcome, Outcome::Received { .. } | Outcome::Dropped) {
                self.log.push(LoggedFrame {
                    t_us: (event.end_ns / 1000).saturating_sub(self.start_us),
                    frame: event.frame,
                    sender: self.node_names[event.from.index()],
                });
            }
        }
    }
}

fn node_of(name: &str) -> Option<Node> {
    Node::ALL.iter().copied().find(|n| n.name() == name)
}
