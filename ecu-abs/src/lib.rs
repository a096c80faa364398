//! ABS / brakes ECU (node 0x0E), spec section 2 and the report's pseudocode 5.2.1.2.
//!
//! Reads the four wheel speeds (FL, FR, RL, RR, linear speed ω·r in km/h) and drives the
//! four brake actuators. The brake command comes from the pedals ECU (PedalBrake: the
//! driver's pedal or the cruise control's deceleration), the vehicle speed reference from
//! the cruise ECU (VehicleSpeedMsg).
//!
//! # Anti-lock braking
//!
//! While the driver brakes (command above [`BRAKING_THRESHOLD`]) above
//! [`ABS_MIN_SPEED_KMH`], the ECU computes each wheel's slip
//! `(v − v_wheel) / max(v, SLIP_SPEED_FLOOR_KMH)`, where `v` is its own estimate of the
//! vehicle speed, finer than VehicleSpeedMsg's 1 km/h (see `AbsEcu::speed_reference`). A
//! wheel whose slip exceeds [`SLIP_THRESHOLD`] is slipping: its control channel engages and a PID on the slip error
//! (`slip − target`, the target just below the tyre's peak-friction slip) computes an ABS
//! release command in 0..100. The brake applied to each wheel is the driver's command
//! minus the release, limited to [0, 100]; it is never above the driver's command.
//!
//! - **Slip target: the tyre's own friction peak.** [`SLIP_TARGET`] is just below the
//!   peak-friction slip of a tyre on dry asphalt. On ice and snow the peak lies at a few
//!   per cent (Burckhardt's friction curves; so do the vehicle model's tyres, whose slip
//!   stiffness does not depend on the road), and a wheel held at 12 % there is far past
//!   its peak: it has lost a part of its braking force and nearly all its side force.
//!   Other low-friction surfaces (wet cobblestones) peak at 12–15 % like asphalt, so the
//!   ECU does not guess the peak from the friction: it measures it. When a channel has to
//!   release its wheel completely (see *Saturation* below), the wheel spins back up under
//!   its tyre's force alone, so its acceleration is largest at the slip of the friction
//!   peak. From then on the channel regulates to [`PEAK_TARGET_FRACTION`] of the slip at
//!   that hardest acceleration (between [`SLIP_TARGET_MIN`] and [`SLIP_TARGET_MAX`]). The
//!   measurement only counts if the wheel was seen accelerating harder towards the peak
//!   (by [`PEAK_RISE_FACTOR`] to [`PEAK_RISE_MAX_FACTOR`]; more means the road changed)
//!   after the brake pressure had fallen ([`PEAK_LEARN_SETTLE_S`]), so a fast recovery on
//!   a high-friction road teaches nothing and keeps [`SLIP_TARGET`]. If the road gets
//!   better (the car decelerates more than the learned peak suggests), the target follows
//!   the deceleration up again: [`SLIP_TARGET`] × deceleration /
//!   [`DECEL_AT_FULL_FRICTION_MPS2`] (deceleration from VehicleSpeedMsg, low-pass filtered
//!   over [`DECEL_FILTER_TAU_S`]). A new stop starts again from [`SLIP_TARGET`].
//! - **Peak seeking while regulating.** On wet roads (friction 0.4–0.6) the peak lies at
//!   5–8 % slip, but a released wheel spins back up through it within a step or two,
//!   before the pressure has fallen: nothing is learned there, and at 12 % slip the
//!   vehicle model's tyres give 3–9 % less than their peak. So while every engaged
//!   channel regulates its wheel (no full release, a release acting, the yaw-moment limit
//!   not holding a wheel back), the ECU steps a factor on all slip targets and watches the
//!   brake torque all the brakes apply, which in steady regulation is the force the tyres
//!   transmit (extremum seeking). Each step lasts [`SEEK_PERIOD_US`], measured after
//!   [`SEEK_SETTLE_US`]; the factor keeps going the way the torque grows, turns back with
//!   half the step when it falls by more than [`SEEK_TOLERANCE`], and on the flat top
//!   prefers the lower slip, where the tyre keeps more side force. All four brakes
//!   together, not each channel's: the four-wheel drive's differentials and centre
//!   viscous coupling tie the wheels together even in neutral, so one channel's brake
//!   partly holds the others' wheels (sought per channel, the front targets climbed to
//!   8 % on ice whose tyres peak at 2.6 %). Nothing is assumed about the tyre: on the test
//!   plant's tyre, peaking at 15 %, the factor goes up instead.
//! - **Pressure hold.** The brake pressure lags the command (calibration
//!   [`BRAKE_APPLY_TAU_S`], [`BRAKE_RELEASE_TAU_S`]), so the ECU follows what each channel's
//!   pressure has built up to. When a channel engages, its release starts from that
//!   pressure instead of from the driver's full command: a wheel that runs into lock while
//!   the pressure is still rising gets it held at once. (Released from the full command,
//!   the pressure kept rising for another 10–15 ms; the first cycle overshot to 20–32 %
//!   slip on friction 0.6–1.0 and stalled there for a fifth of a second.) While a wheel
//!   slips less than its target, the release unwinds faster ([`UNWIND_KI`]).
//! - **Channels.** Three, as in a classic 3-channel ABS: front left and front right are
//!   controlled individually (the fronts carry most of the braking); the rear axle is one
//!   channel controlled on the rear wheel with the *larger* slip, and both rear wheels get
//!   its release (**select-low**: the rear brakes never exceed what the lower-friction rear
//!   wheel can take). On split-μ the rear axle then keeps its side grip and builds no yaw
//!   moment, so the car keeps its heading; the cost is a little rear braking on the
//!   high-μ side.
//! - **Yaw-moment limit on the front axle** (modified individual control): while the front
//!   axle is under ABS control, the front wheel braked harder may exceed the other's
//!   applied brake by at most a margin that starts at [`YAW_DELAY_INITIAL_MARGIN`] and
//!   grows at [`YAW_DELAY_MARGIN_RATE_PER_S`]. On split friction the front axle thus brakes
//!   almost select-low: the high-friction side adds little yaw moment, which matters
//!   because the ABS cannot count on the driver counter-steering (the virtual car's driver
//!   holds the wheel straight). On even friction both fronts brake alike and the limit
//!   does nothing.
//! - **Saturation (pulsing).** When a channel's release reaches the driver's command (the
//!   wheel's brake is released completely), the wheel is held released until it has spun
//!   back up: its slip below [`RECOVERED_SLIP`], or its acceleration fallen to
//!   [`PEAK_PASSED_FRACTION`] of its maximum (past the friction peak), at most
//!   [`RECOVERY_TIMEOUT_US`]. Then the controller is reset, as the report's ABS did, but to
//!   the brake the tyre was measured to carry rather than to zero: the unbraked wheel's
//!   hardest acceleration `a` gives the tyre's torque `I·a/r` (calibration:
//!   [`WHEEL_INERTIA_KGM2`], [`WHEEL_RADIUS_M`], [`BRAKE_TORQUE_AT_FULL_NM`]), and the brake
//!   returns at [`REAPPLY_FRACTION`] of it (a pressure memory). Between saturations the
//!   integral holds at most the driver's command: anti-windup against the real actuator
//!   limit (the driver's command, not 100). The pressure pulses around the level the road
//!   can take. (The report's reset to zero threw away the integral, which on a
//!   low-friction road *is* the release the wheel needs: the controller re-applied its
//!   P-term brake, 10–20 %, while the wheel was still deep in slip. A front tyre on
//!   μ = 0.2 carries only ≈ 9 % of the front brake, so the released wheel stayed ≈ 30 km/h
//!   slow.)
//! - **Timeout.** The ABS has *acted* in a step when a wheel was slipping or a release of
//!   at least [`RELEASE_ACTIVE_MIN`] was commanded. After [`ABS_TIMEOUT_US`] without
//!   acting, every channel disengages: PIDs reset, release 0, so the next event starts
//!   from a clean controller.
//! - Below [`ABS_MIN_SPEED_KMH`] or without braking the ABS is off and its controllers are
//!   reset: the wheels may lock for the last metres so that the car comes to rest.
//!
//! # Traction control
//!
//! When the driver is not braking, a wheel spins when it is faster than the vehicle by more
//! than [`TC_MIN_EXCESS_KMH`] and by a slip `(v_wheel − v) / max(v, TC_SPEED_FLOOR_KMH)`
//! above [`TC_SLIP_THRESHOLD`] (the EVO is four-wheel drive: all wheels are watched). A PI
//! on the worst wheel's slip above [`TC_SLIP_TARGET`] gives the traction-control cut
//! (TracMsg, 0..100; the pedals ECU scales the accelerator by `1 − cut/100`). It stays in
//! control while a wheel spins or the cut is at least [`CUT_ACTIVE_MIN`], and disengages
//! (cut 0, controller reset) after [`TC_HOLD_US`] of neither. Braking turns it off.
//!
//! # Safe states (inputs stale after 3 periods, 30 ms)
//!
//! - **VehicleSpeedMsg stale** (no speed reference): ABS and traction control are
//!   inactive, the driver's brake passes through unmodified to all four wheels, the cut is
//!   0; DTC "lost communication with the cruise ECU". They resume when the frames return.
//! - **PedalBrake stale** (driver's brake unknown): the last good command is kept for
//!   [`PEDAL_LOSS_HOLD_US`] (a short gap must not drop an emergency stop), then the ECU
//!   brings the car to a controlled stop: the command rises at
//!   [`CONTROLLED_STOP_RAMP_PER_S`] to `max(last good, CONTROLLED_STOP_BRAKE)` and holds
//!   the car at rest afterwards. Why not release: the pedals ECU also drives the
//!   accelerator and is the only way the driver brakes, so a car without it cannot be
//!   controlled and must not keep rolling; a moderate, ramped brake is a predictable stop
//!   for the traffic behind, and never less than what the driver last asked for. The ABS
//!   keeps working on this command. DTC "lost communication with the pedals ECU". The
//!   driver's command is taken again as soon as the frames return.
//! - **Wheel speed sensor implausible**: a reading that is not a finite speed in
//!   0..=[`WHEEL_SPEED_MAX_KMH`] disables ABS and traction control at once for that step
//!   (pass-through). A reading that stays invalid, or more than
//!   [`WHEEL_PLAUSIBILITY_DIFF_KMH`] away from all three others, for
//!   [`WHEEL_PLAUSIBILITY_DEBOUNCE_US`] records the wheel's chassis DTC
//!   ([`WHEEL_SENSOR_DTCS`]: C0035 FL, C0040 FR, C0045 RL, C0050 RR, failure type 0x64
//!   "signal plausibility failure") and disables ABS and traction control (pass-through)
//!   until the ECU restarts, as an ABS warning lamp does. The DTC's test-failed bit clears
//!   when the reading is plausible again; the code stays stored.
//! - An invalid frame records "invalid data" against its sender and keeps the last good
//!   value (a sender of only invalid frames goes stale like a silent one).
//!
//! [`Variant::Faulty`] is the "faulty software" of the report's second demonstration: the
//! ABS never releases (release always 0, applied brake = driver brake even when the wheels
//! lock), so hard braking locks the wheels and the car loses its heading. Everything else
//! (traction control, messages, safe states) works as in the correct build. Firmware
//! selects it with a `faulty` feature; the virtual car picks it per scenario.
#![no_std]
#![deny(missing_docs)]

pub mod pins;

use autoplug_can::{AbsMsg, Frame, Node, PedalBrake, TracMsg, VehicleSpeedMsg, WheelSpeedMsg};
use autoplug_ecu::{receive, supervise, Dtcs, EcuLogic, Input, Instant, PeriodicTx};
use autoplug_pid::{Pid, PidConfig};

pub use autoplug_ecu::Variant;

// The published parameters (calibration, thresholds, trouble codes) live with the
// other ECUs' in `autoplug-ecu-params`, where the gateway's diagnostics read them.
pub use autoplug_ecu_params::abs::*;

/// The variant this build runs: [`Variant::Faulty`] with the `faulty` cargo feature (the
/// demonstration's broken firmware), [`Variant::Correct`] otherwise. The virtual car
/// chooses per scenario instead.
pub const BUILD_VARIANT: Variant = if cfg!(feature = "faulty") {
    Variant::Faulty
} else {
    Variant::Correct
};

/// The part number of this ECU's software (UDS 0xF187), as the virtual car's ECUs answer
/// it.
pub const PART_NUMBER: &str = "AP-ABS-0001";

/// Control period. Wheel dynamics are fast (a wheel locks within ~100 ms at full brake), so
/// the ABS runs at twice the message rate; messages still go out at their 10 ms periods
/// (or on change, at most every 5 ms). A PedalBrake frame that starts a braking gets a
/// step of its own at once (`EcuLogic::step_requested`), the period counting from it.
pub const STEP_PERIOD_US: u64 = 5_000;

/// Brake onsets closer together than this get no step of their own (they wait for the
/// period): no foot presses a pedal twice in a tenth of a second, and a bus flooded with
/// alternating PedalBrake frames must not make the ECU step at the flood's rate.
pub const ONSET_STEP_MIN_GAP_US: u64 = 100_000;

/// Driver brake command (0..100) above which the driver is braking. Small, above the
/// 1-unit resolution of PedalBrake, so a resting foot does not enable the ABS.
pub const BRAKING_THRESHOLD: f32 = 2.0;

/// Vehicle speed below which the ABS is off (km/h): the wheels may lock for the last metres
/// so that the car comes to rest, and the 1 km/h speed reference is too coarse there.
pub const ABS_MIN_SPEED_KMH: f32 = 5.0;

/// Wheel speed at or above which a wheel counts as turning, km/h: the ABS ECU refuses to be
/// reprogrammed then, whatever VehicleSpeedMsg says (the UDS server's standstill limit).
pub const WHEEL_TURNING_KMH: f32 = 1.0;

/// Slip above which a wheel is slipping and its ABS channel engages. Just below the target
/// so that an engaged channel keeps being seen as acting while it regulates.
pub const SLIP_THRESHOLD: f32 = 0.10;

/// Slip the ABS regulates to until a channel has measured its tyre's friction peak: just
/// below the peak-friction slip on a high-friction road (~0.13), on the stable side of the
/// friction curve where the tyre still steers.
pub const SLIP_TARGET: f32 = 0.12;

/// Smallest slip target, for ice: its peak-friction slip is a few per cent. Also keeps
/// the target clear of the 1 km/h resolution of the speed reference.
pub const SLIP_TARGET_MIN: f32 = 0.03;

/// A channel that has measured its tyre's peak-friction slip regulates to this fraction
/// of it: just on the stable side of the peak, where the tyre still has side force.
pub const PEAK_TARGET_FRACTION: f32 = 0.9;

/// While a released wheel spins back up, its acceleration is not used for this long after
/// the release, s: the brake pressure is still falling (about four of its time constants),
/// so the acceleration says more about the brake than about the tyre.
pub const PEAK_LEARN_SETTLE_S: f32 = 0.08;

/// Least wheel acceleration (ω̇·r, m/s²) that counts as a tyre pulling its wheel back up:
/// a front tyre on ice (μ = 0.2) gives about 50–70 m/s².
pub const PEAK_LEARN_MIN_ACCEL_MPS2: f32 = 10.0;

/// A released wheel's acceleration must have risen by at least this factor above its
/// first valid sample for its maximum to count as the tyre's peak (the recovery started
/// beyond the peak, on the falling side of the friction curve, and went through it) ...
pub const PEAK_RISE_FACTOR: f32 = 1.1;

/// ... and by at most this factor: a sliding tyre keeps 0.6–0.9 of its peak friction, so a
/// larger rise means the road changed under the wheel (ice to asphalt), not a peak.
pub const PEAK_RISE_MAX_FACTOR: f32 = 2.0;

/// A released wheel has passed its tyre's friction peak when its acceleration has fallen
/// below this fraction of the largest value seen: the release ends, and the slip at which
/// the wheel accelerated hardest is the tyre's peak-friction slip.
pub const PEAK_PASSED_FRACTION: f32 = 0.85;

/// A released wheel whose slip is below this has spun back up: the release ends (and the
/// peak is taken where the wheel accelerated hardest, if it had not been seen to pass).
pub const RECOVERED_SLIP: f32 = 0.03;

/// Largest slip target a measured peak can give: tyres on some surfaces peak at 15–20 %.
pub const SLIP_TARGET_MAX: f32 = 0.18;

/// A channel released completely watches its wheel spin back up (and holds the release
/// until it has) only once the slip is this far past the target: a wheel running into
/// lock, not one a little over the target, which the controller brings back by itself.
pub const RECOVERY_SLIP_FACTOR: f32 = 1.5;

/// Longest full release while a wheel spins back up, µs; a recovery that takes longer
/// teaches nothing.
pub const RECOVERY_TIMEOUT_US: u64 = 600_000;

/// After a full release the brake returns at this fraction of the torque the tyre was
/// measured to carry (the unbraked wheel's hardest acceleration), so the wheel comes back
/// just under its peak instead of from zero or from full brake.
pub const REAPPLY_FRACTION: f32 = 0.9;

/// Calibration of the EVO VI's brakes: brake torque at 100 % command, N·m, per channel
/// (front left, front right, rear), as in the vehicle model's parameters (Brembo 4-pot
/// front, 2-pot rear).
pub const BRAKE_TORQUE_AT_FULL_NM: [f32; 3] = [3000.0, 3000.0, 1400.0];

/// Calibration: rotating inertia of one wheel with its brake disc and half shaft, kg·m².
pub const WHEEL_INERTIA_KGM2: f32 = 1.2;

/// Calibration: time constant of the brake pressure rising to the command, s (booster,
/// master cylinder and inlet valves of the EVO's hydraulics, as the vehicle model has
/// them). The ECU follows the pressure it cannot measure with it (the pressure hold in
/// the crate documentation).
pub const BRAKE_APPLY_TAU_S: f32 = 0.04;

/// Calibration: time constant of the brake pressure falling to the command, s (outlet
/// valves into the low-pressure accumulator).
pub const BRAKE_RELEASE_TAU_S: f32 = 0.02;

/// Calibration: rolling radius of the 225/45 ZR17 tyres, m.
pub const WHEEL_RADIUS_M: f32 = 0.31;

/// Deceleration the car reaches under ABS on a road of friction 1 (dry asphalt), m/s²
/// (0.92 g): once a channel has learned a low peak slip, its target rises again with the
/// deceleration relative to this (a better road).
pub const DECEL_AT_FULL_FRICTION_MPS2: f32 = 9.0;

/// Time constant of the low-pass filter on the vehicle deceleration, s: smooths the
/// 1 km/h steps of VehicleSpeedMsg (one every 30 ms at 1 g, every 140 ms on ice) and
/// still follows a change of road within half a second. The start of a stop weighs most
/// (the car is fastest): at 0.3 s the estimate, and the speed reference and the slip
/// target floor built on it, lagged the first half second (µ 1.0 from 50 km/h: 1.070 ×
/// v²/(2µg), 1.063 at 0.15 s).
pub const DECEL_FILTER_TAU_S: f32 = 0.15;

/// Peak seeking: the factor on the slip targets moves one step, then stays for this long,
/// µs, while the brake torque is measured (at least two cycles of the pressure's pulsing,
/// so that its mean is steady).
pub const SEEK_PERIOD_US: u64 = 200_000;

/// Peak seeking: the brake torque is measured only from this long after the factor moved,
/// µs, once the wheels have settled at their new slip.
pub const SEEK_SETTLE_US: u64 = 80_000;

/// Peak seeking: the first step of the factor, as a fraction of it (down first: a tyre on
/// a wet road peaks below [`SLIP_TARGET`]); halved at each reversal, down to
/// [`SEEK_STEP_MIN`].
pub const SEEK_STEP_INITIAL: f32 = 0.2;

/// Peak seeking: the smallest step, as a fraction of the factor.
pub const SEEK_STEP_MIN: f32 = 0.05;

/// Peak seeking: the smallest factor on the slip targets (a quarter of [`SLIP_TARGET`]
/// reaches the peak of ice; [`SLIP_TARGET_MIN`] bounds the target itself) ...
pub const SEEK_SCALE_MIN: f32 = 0.25;

/// ... and the largest ([`SLIP_TARGET_MAX`] bounds the target itself).
pub const SEEK_SCALE_MAX: f32 = 1.5;

/// Peak seeking: the brake torque must change by more than this fraction for a step to
/// count as better or worse; within it the tyres are on the flat top of their curve.
pub const SEEK_TOLERANCE: f32 = 0.01;

/// VehicleSpeedMsg carries the speed rounded to its resolution (the DBC's factor, 1 km/h):
/// the true speed is within half a step of it.
pub const SPEED_MSG_ROUNDING_KMH: f32 = VehicleSpeedMsg::VEHICLE_SPEED.factor() / 2.0;

/// How old the speed in a VehicleSpeedMsg is when the ABS uses it, at most, s: one cycle of
/// the message (the cruise ECU measures, then sends), a millisecond for the frame and its
/// queue, and one ABS step.
pub const SPEED_MSG_AGE_S: f32 =
    VehicleSpeedMsg::CYCLE_TIME_MS as f32 * 1e-3 + 1e-3 + STEP_PERIOD_US as f32 * 1e-6;

/// Slip is computed relative to at least this speed (km/h): below it the thresholds act
/// as an absolute speed difference (0.10 × 10 = 1 km/h), so that the last metres, where
/// the speed reference's remaining error is a large part of the speed, do not look like
/// slip.
pub const SLIP_SPEED_FLOOR_KMH: f32 = 10.0;

/// PID on the slip error (release in % of full brake per unit of slip). Mostly P + D: the
/// derivative of slip is the early warning of a wheel running into lock (and of it
/// spinning back up); the integral holds the release the road's friction needs.
pub const ABS_TUNING: PidConfig = PidConfig {
    kp: 400.0,
    ki: 1500.0,
    kd: 4.0,
    derivative_filter_tau_s: 0.01,
    output_min: 0.0,
    output_max: 100.0,
};

/// Front-axle yaw-moment limit: while the front axle is under ABS control, the front wheel
/// braked harder may exceed the other's applied brake by at most this margin at first, in
/// percentage points: on split friction the front axle starts select-low...
///
/// Why so strict: each point of front brake difference is ≈ 30 N·m of brake torque, a
/// yaw moment of ≈ 75 N·m. With the low-friction tyres braking at their limit the car
/// has only about half its cornering stiffness to resist it, and a yaw moment of a few
/// hundred N·m held for the ten seconds of a stop on ice turns an uncorrected car by
/// 10–20°; the high-friction side's extra braking would shorten that stop by only a few
/// per cent.
pub const YAW_DELAY_INITIAL_MARGIN: f32 = 0.0;

/// ... and the margin then grows at this rate, %/s: a slow build-up (a real yaw-moment
/// build-up delay reaches full asymmetry within a second or two, for a driver who
/// counter-steers), so that the yaw moment stays small while the speed is high. The stop
/// from 160 km/h on ice beside asphalt takes 14 s: when the rate was chosen the car, wheel
/// held straight, turned 17° by its end at 0.3 %/s and 7.6° at 0.1 %/s for 3 % more
/// distance; with no build-up at all it stopped longer than on ice all round. With the
/// channel control of today it turns 6.3° and stops in 435 m, shorter than the 446 m on
/// ice all round (`virtual-car abs-sweep`).
pub const YAW_DELAY_MARGIN_RATE_PER_S: f32 = 0.1;

/// Extra integral gain (release per unit of slip per second) while a wheel slips less than
/// its target: an under-braked wheel (the road got better, or the pressure hold let go
/// too much) gets its brake back at the PID's integral rate plus this one, so that the
/// release built up on ice unwinds within a few tenths of a second on asphalt, while the
/// integral stays gentle on the way up, where a faster one set the brake pulsing on ice.
pub const UNWIND_KI: f32 = 2000.0;

/// The ABS channel controller, built at compile time: an invalid tuning fails the build.
const ABS_PID: Pid = Pid::from_tuning(ABS_TUNING);

/// A release at least this large (0..100) counts as the ABS acting, for the timeout.
pub const RELEASE_ACTIVE_MIN: f32 = 1.0;

/// ABS timeout: without acting for this long, the ABS disengages and resets (µs).
pub const ABS_TIMEOUT_US: u64 = 1_000_000;

/// Traction control: a wheel faster than the vehicle by at least this much can be spinning
/// (km/h), so that speed-sensor rounding at a standstill is not mistaken for spin.
pub const TC_MIN_EXCESS_KMH: f32 = 3.0;

/// Traction control: drive slip above which a wheel is spinning.
pub const TC_SLIP_THRESHOLD: f32 = 0.15;

/// Traction control: drive slip the cut regulates to (near the tyre's peak traction).
pub const TC_SLIP_TARGET: f32 = 0.10;

/// Traction control: drive slip is computed relative to at least this speed (km/h), so a
/// launch from rest has a finite slip.
pub const TC_SPEED_FLOOR_KMH: f32 = 10.0;

/// A cut at least this large (0..100) counts as traction control acting.
pub const CUT_ACTIVE_MIN: f32 = 1.0;

/// Traction control disengages (cut 0, controller reset) after this long without a
/// spinning wheel or a cut of at least [`CUT_ACTIVE_MIN`] (µs).
pub const TC_HOLD_US: u64 = 300_000;

/// PI on the drive slip error: cut in % of the accelerator per unit of slip. The integral
/// holds the cut the road's grip needs and gives it back within a second or so once the
/// wheels grip.
pub const TC_TUNING: PidConfig = PidConfig {
    kp: 300.0,
    ki: 1000.0,
    kd: 0.0,
    derivative_filter_tau_s: 0.0,
    output_min: 0.0,
    output_max: 100.0,
};

/// The traction controller, built at compile time.
const TC_PID: Pid = Pid::from_tuning(TC_TUNING);

/// PedalBrake lost: the last good command is kept this long before the controlled stop
/// (µs), so that a short gap does not change the braking.
pub const PEDAL_LOSS_HOLD_US: u64 = 500_000;

/// PedalBrake lost: brake command (0..100) of the controlled stop, a moderate deceleration.
pub const CONTROLLED_STOP_BRAKE: f32 = 30.0;

/// PedalBrake lost: how fast the command rises to the controlled stop (per second), so the
/// traffic behind sees a progressive stop rather than a jolt.
pub const CONTROLLED_STOP_RAMP_PER_S: f32 = 100.0;

/// Highest wheel speed a sensor can plausibly report (km/h).
pub const WHEEL_SPEED_MAX_KMH: f32 = 400.0;

/// A wheel speed this far (km/h) from all three others is implausible.
pub const WHEEL_PLAUSIBILITY_DIFF_KMH: f32 = 50.0;

/// An implausible wheel speed sets its DTC after this long (µs). Longer than any wheel
/// lock the correct ABS allows, so braking does not trip it.
pub const WHEEL_PLAUSIBILITY_DEBOUNCE_US: u64 = 500_000;

/// ABS control channels: front left, front right, rear axle (select-low).
const CHANNELS: usize = 3;

/// What a channel's full release does in this step.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Release {
    /// No full release in progress.
    None,
    /// The wheel is still spinning back up: keep the brake released.
    Holding,
    /// The wheel has spun back up: brake again, at this brake command (0..100) if the
    /// tyre's force could be measured.
    Ended(Option<f32>),
}

/// A completely released wheel spinning back up, watched for its tyre's friction peak.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Recovery {
    /// When the release began.
    since: Instant,
    /// The first wheel acceleration seen after the settling time, m/s².
    first_accel_mps2: Option<f32>,
    /// Largest wheel acceleration seen after the settling time, m/s².
    max_accel_mps2: f32,
    /// The channel's slip at that acceleration.
    slip_at_max: f32,
}

/// The search for the tyres' friction peak while the channels regulate (extremum seeking,
/// see the crate's documentation): a factor on every channel's slip target, stepped the
/// way the brake torque the tyres carry grows.
#[derive(Clone, Copy, Debug, PartialEq)]
struct PeakSeek {
    /// Factor on every channel's slip target.
    scale: f32,
    /// Step of the factor, as a fraction of it.
    step: f32,
    /// Whether the last step raised the slip.
    raising: bool,
    /// When the measurement at the present factor began; `None` until the channels
    /// regulate again.
    since: Option<Instant>,
    /// Sum of the brake torque over the measurement, and the number of samples.
    torque_sum: f32,
    samples: f32,
    /// Mean brake torque at the previous factor (0 before the first).
    last_mean: f32,
}

impl PeakSeek {
    const NEW: Self = Self {
        scale: 1.0,
        step: SEEK_STEP_INITIAL,
        raising: false,
        since: None,
        torque_sum: 0.0,
        samples: 0.0,
        last_mean: 0.0,
    };

    /// Drops the measurement: it starts again when the channels regulate again.
    fn restart(&mut self) {
        self.since = None;
        self.torque_sum = 0.0;
        self.samples = 0.0;
    }

    /// Takes one step's brake torque, and moves the factor when a period is over.
    fn update(&mut self, now: Instant, torque: f32) {
        let elapsed = now.micros_since(*self.since.get_or_insert(now));
        if elapsed < SEEK_SETTLE_US {
            return;
        }
        self.torque_sum += torque;
        self.samples += 1.0;
        if elapsed < SEEK_PERIOD_US {
            return;
        }
        let mean = self.torque_sum / self.samples;
        if mean < self.last_mean * (1.0 - SEEK_TOLERANCE) {
            // Worse: turn back, with a smaller step.
            self.raising = !self.raising;
            self.step = (self.step * 0.5).max(SEEK_STEP_MIN);
        } else if mean <= self.last_mean * (1.0 + SEEK_TOLERANCE) {
            // Flat: prefer the lower slip, where the tyre keeps more side force.
            self.raising = false;
        } else {
            // Better: go on, with a larger step again (a turn on a noisy period would
            // otherwise leave the smallest step to crawl back).
            self.step = (self.step * 1.25).min(SEEK_STEP_INITIAL);
        }
        self.last_mean = mean;
        let factor = if self.raising {
            1.0 + self.step
        } else {
            1.0 - self.step
        };
        self.scale = limit(self.scale * factor, SEEK_SCALE_MIN, SEEK_SCALE_MAX);
        self.restart();
    }
}

/// Sensor readings.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Sensors {
    /// Linear wheel speeds ω·r, km/h, FL, FR, RL, RR.
    pub wheel_speed_kmh: [f32; 4],
}

/// Actuator commands.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Actuators {
    /// Brake applied per wheel, FL, FR, RL, RR, 0..100 (% of full brake torque).
    pub brake: [f32; 4],
}

/// Whether the ABS and traction control may act.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub enum Availability {
    /// Inputs good: ABS and traction control work.
    #[default]
    Available,
    /// VehicleSpeedMsg stale: the driver's brake passes through.
    NoSpeedReference,
    /// A wheel speed reading is invalid now, or a sensor fault was confirmed: the
    /// driver's brake passes through.
    WheelSensorFault,
}

/// Where the brake command the ECU works with comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub enum BrakeSource {
    /// PedalBrake, fresh.
    #[default]
    Driver,
    /// PedalBrake stale: the last good command, held.
    HoldLast,
    /// PedalBrake stale for longer than the hold: controlled stop.
    ControlledStop,
}

/// What the ECU decided in its last step, for logs and the virtual car's trace.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Status {
    /// Whether ABS and traction control may act.
    pub availability: Availability,
    /// Where the brake command came from.
    pub brake_source: BrakeSource,
    /// The brake command used (the driver's, or the fail-safe one), 0..100.
    pub driver_brake: f32,
    /// ABS release per wheel, FL, FR, RL, RR, 0..100.
    pub release: [f32; 4],
    /// Brake applied per wheel, FL, FR, RL, RR, 0..100.
    pub brake: [f32; 4],
    /// Whether any ABS channel is engaged.
    pub abs_active: bool,
    /// Slip each ABS channel regulates to (front left, front right, rear axle).
    pub slip_target: [f32; 3],
    /// Whether traction control is engaged.
    pub traction_active: bool,
    /// Traction-control cut, 0..100.
    pub traction_cut: f32,
}

/// The ABS / brakes ECU's logic.
#[derive(Clone, Debug)]
pub struct AbsEcu {
    variant: Variant,
    vehicle_speed: Input<VehicleSpeedMsg>,
    pedal_brake: Input<PedalBrake>,
    abs_pids: [Pid; CHANNELS],
    engaged: [bool; CHANNELS],
    abs_last_acted: Option<Instant>,
    /// Allowed front-axle brake difference while the front axle is under control, %.
    yaw_delay_margin: Option<f32>,
    /// Low-pass filtered vehicle deceleration while braking, m/s², for the slip target.
    decel_mps2: f32,
    /// The speed reference at the previous braking step, km/h.
    previous_speed_kmh: Option<f32>,
    /// The ABS's own estimate of the vehicle speed while braking, km/h (see
    /// [`AbsEcu::speed_reference`]).
    speed_estimate_kmh: Option<f32>,
    /// Wheel speeds at the previous braking step, km/h.
    previous_wheels_kmh: Option<[f32; 4]>,
    /// A PedalBrake frame since the last step took the brake command from released to
    /// braking: the runtime steps at once.
    brake_onset: bool,
    /// When the last onset asked for a step (see [`ONSET_STEP_MIN_GAP_US`]).
    last_onset: Option<Instant>,
    /// Per channel: a full release in progress, watched for the friction peak.
    recovery: [Option<Recovery>; CHANNELS],
    /// Per channel: the tyre's peak-friction slip, once measured in this stop.
    peak_slip: [Option<f32>; CHANNELS],
    /// Per channel: the brake pressure as the hydraulics have built it, 0..100.
    pressure_estimate: [f32; CHANNELS],
    /// The search for the tyres' friction peak.
    seek: PeakSeek,
    tc_pid: Pid,
    tc_last_acted: Option<Instant>,
    pedal_lost_since: Option<Instant>,
    failsafe_brake: f32,
    implausible_since: [Option<Instant>; 4],
    sensor_fault: bool,
    /// At the last step, valid wheel speeds showed a wheel turning.
    wheels_turning: bool,
    status: Status,
    last_step: Option<Instant>,
    tx_wheels: PeriodicTx,
    tx_abs: PeriodicTx,
    tx_trac: PeriodicTx,
    dtcs: Dtcs,
}

impl AbsEcu {
    /// The ECU at power-up (`now`), running `variant`.
    pub fn new(variant: Variant, now: Instant) -> Self {
        Self {
            variant,
            vehicle_speed: Input::new(now),
            pedal_brake: Input::new(now),
            abs_pids: [ABS_PID; CHANNELS],
            engaged: [false; CHANNELS],
            abs_last_acted: None,
            yaw_delay_margin: None,
            decel_mps2: 0.0,
            previous_speed_kmh: None,
            speed_estimate_kmh: None,
            previous_wheels_kmh: None,
            brake_onset: false,
            last_onset: None,
            recovery: [None; CHANNELS],
            peak_slip: [None; CHANNELS],
            pressure_estimate: [0.0; CHANNELS],
            seek: PeakSeek::NEW,
            tc_pid: TC_PID,
            tc_last_acted: None,
            pedal_lost_since: None,
            failsafe_brake: 0.0,
            implausible_since: [None; 4],
            sensor_fault: false,
            wheels_turning: false,
            status: Status::default(),
            last_step: None,
            tx_wheels: PeriodicTx::of::<WheelSpeedMsg>(),
            tx_abs: PeriodicTx::of::<AbsMsg>(),
            tx_trac: PeriodicTx::of::<TracMsg>(),
            dtcs: Dtcs::new(),
        }
    }

    /// The software variant running.
    pub fn variant(&self) -> Variant {
        self.variant
    }

    /// What the last step decided.
    pub fn status(&self) -> Status {
        self.status
    }

    /// Whether a wheel speed sensor fault was confirmed (ABS off until restart).
    pub fn wheel_sensor_fault(&self) -> bool {
        self.sensor_fault
    }

    /// Checks the wheel speed readings: returns them with invalid ones replaced by 0, and
    /// whether all four are valid now. Debounces implausible readings into the DTCs.
    fn check_wheel_sensors(&mut self, now: Instant, raw: &[f32; 4]) -> ([f32; 4], bool) {
        // Plain index loops: the same checks as iterator chains took 88 bytes more of the
        // firmware.
        let mut sanitized = [0.0f32; 4];
        let mut all_valid = true;
        for i in 0..4 {
            let w = raw[i];
            // Not a NaN or an infinity: neither lies in the range.
            let ok = (0.0..=WHEEL_SPEED_MAX_KMH).contains(&w);
            all_valid &= ok;
            if ok {
                sanitized[i] = w;
            }
            let mut isolated = true;
            for (j, other) in raw.iter().enumerate() {
                let far = (w - other).abs() > WHEEL_PLAUSIBILITY_DIFF_KMH;
                isolated &= j == i || far;
            }
            let dtc = WHEEL_SENSOR_DTCS[i];
            if ok && !isolated {
                self.implausible_since[i] = None;
                self.dtcs.report_passed(dtc);
                continue;
            }
            let first = *self.implausible_since[i].get_or_insert(now);
            if now.micros_since(first) >= WHEEL_PLAUSIBILITY_DEBOUNCE_US {
                if self.dtcs.report_failed(dtc, now) {
                    autoplug_log::warn!("abs: wheel {} speed sensor implausible, DTC", i);
                }
                if !self.sensor_fault {
                    autoplug_log::warn!("abs: wheel sensor fault, ABS off until restart");
                    self.sensor_fault = true;
                }
            }
        }
        (sanitized, all_valid)
    }

    /// The brake command to work with: the driver's, or the fail-safe one when PedalBrake
    /// is stale.
    fn brake_command(&mut self, now: Instant, pedal_stale: bool, dt_s: f32) -> (f32, BrakeSource) {
        let last_good = limit(self.pedal_brake.value().brake_cmd, 0.0, 100.0);
        if !pedal_stale {
            self.pedal_lost_since = None;
            self.failsafe_brake = last_good;
            return (last_good, BrakeSource::Driver);
        }
        let since = *self.pedal_lost_since.get_or_insert(now);
        if now.micros_since(since) < PEDAL_LOSS_HOLD_US {
            self.failsafe_brake = last_good;
            return (last_good, BrakeSource::HoldLast);
        }
        if self.status.brake_source != BrakeSource::ControlledStop {
            autoplug_log::warn!("abs: brake command lost, controlled stop");
        }
        let target = last_good.max(CONTROLLED_STOP_BRAKE);
        self.failsafe_brake = limit(
            self.failsafe_brake + CONTROLLED_STOP_RAMP_PER_S * dt_s,
            0.0,
            target,
        );
        (self.failsafe_brake, BrakeSource::ControlledStop)
    }

    /// Disengages every ABS channel: releases 0, controllers reset.
    fn abs_off(&mut self) {
        self.yaw_delay_margin = None;
        if self.engaged.iter().any(|e| *e) {
            autoplug_log::info!("abs: disengaged");
        }
        self.engaged = [false; CHANNELS];
        self.abs_last_acted = None;
        for pid in &mut self.abs_pids {
            pid.reset();
        }
    }

    /// Forgets what the last stop learned about the road: the next one starts from
    /// [`SLIP_TARGET`].
    fn reset_friction_estimate(&mut self) {
        self.decel_mps2 = 0.0;
        self.previous_speed_kmh = None;
        self.speed_estimate_kmh = None;
        self.previous_wheels_kmh = None;
        self.recovery = [None; CHANNELS];
        self.peak_slip = [None; CHANNELS];
        self.seek = PeakSeek::NEW;
    }

    /// Follows the vehicle deceleration while braking (speed reference `v`, km/h).
    fn update_friction_estimate(&mut self, v: f32, dt_s: f32) {
        if let Some(previous) = self.previous_speed_kmh {
            if dt_s > 0.0 {
                let raw = (previous - v) / 3.6 / dt_s;
                let alpha = dt_s / (DECEL_FILTER_TAU_S + dt_s);
                self.decel_mps2 += (raw - self.decel_mps2) * alpha;
            }
        }
        self.previous_speed_kmh = Some(v);
    }

    /// The vehicle speed the slips are computed against while braking, km/h, finer than
    /// VehicleSpeedMsg's 1 km/h: at 15 km/h on ice one step of it is more slip than the
    /// tyre's peak. The estimate follows the filtered deceleration from step to step and is
    /// held to what the message allows: within its rounding (±0.5 km/h) of the message,
    /// less what the car has lost since the message's speed was measured. No wheel turns
    /// faster than the car while it brakes, so the fastest wheel is a floor.
    fn speed_reference(&mut self, v_msg: f32, wheels: &[f32; 4], dt_s: f32) -> f32 {
        let decel_kmh_s = self.decel_mps2.max(0.0) * 3.6;
        let predicted = self
            .speed_estimate_kmh
            .map_or(v_msg, |v| v - decel_kmh_s * dt_s);
        let high = v_msg + SPEED_MSG_ROUNDING_KMH;
        let low = v_msg - SPEED_MSG_ROUNDING_KMH - decel_kmh_s * SPEED_MSG_AGE_S;
        let fastest_wheel = wheels.iter().fold(0.0f32, |m, &w| m.max(w));
        let v = limit(predicted, low.max(fastest_wheel.min(high)), high);
        self.speed_estimate_kmh = Some(v);
        v
    }

    /// The slip channel `ch` regulates to: [`SLIP_TARGET`] until the channel has measured
    /// its tyre's peak, then just below the peak, or higher if the car decelerates more
    /// than that peak suggests; within [`SLIP_TARGET_MIN`]..=[`SLIP_TARGET_MAX`].
    fn slip_target(&self, ch: usize) -> f32 {
        let friction = limit(self.decel_mps2 / DECEL_AT_FULL_FRICTION_MPS2, 0.0, 1.0);
        let base = self.peak_slip[ch].map_or(SLIP_TARGET, |p| PEAK_TARGET_FRACTION * p);
        let target = (self.seek.scale * base).max(SLIP_TARGET * friction);
        limit(target, SLIP_TARGET_MIN, SLIP_TARGET_MAX)
    }

    /// Follows a completely released wheel spinning back up (slip `slip`, acceleration
    /// `accel_mps2`).
    fn watch_recovery(&mut self, ch: usize, now: Instant, slip: f32, accel_mps2: f32) -> Release {
        let Some(recovery) = self.recovery.get_mut(ch).and_then(|r| r.as_mut()) else {
            return Release::None;
        };
        let elapsed = now.micros_since(recovery.since);
        if elapsed >= (PEAK_LEARN_SETTLE_S * 1e6) as u64 {
            recovery.first_accel_mps2.get_or_insert(accel_mps2);
            if accel_mps2 > recovery.max_accel_mps2 {
                recovery.max_accel_mps2 = accel_mps2;
                recovery.slip_at_max = slip;
            }
        }
        if elapsed >= RECOVERY_TIMEOUT_US {
            self.recovery[ch] = None;
            return Release::Ended(None);
        }
        // A maximum only counts as the friction peak if the wheel was seen accelerating
        // harder towards it: the recovery started beyond the peak and went through it.
        let through_peak = recovery.max_accel_mps2 >= PEAK_LEARN_MIN_ACCEL_MPS2
            && recovery.first_accel_mps2.is_some_and(|first| {
                recovery.max_accel_mps2 >= PEAK_RISE_FACTOR * first
                    && recovery.max_accel_mps2 <= PEAK_RISE_MAX_FACTOR * first
            });
        let peak_passed =
            through_peak && accel_mps2 < PEAK_PASSED_FRACTION * recovery.max_accel_mps2;
        if slip >= RECOVERED_SLIP && !peak_passed {
            return Release::Holding;
        }
        // Spun back up through the friction peak: the hardest acceleration was there.
        let learned = through_peak.then_some(recovery.slip_at_max);
        // The unbraked wheel's hardest acceleration measures the most its tyre carries:
        // ω̇·I = F·r, so a brake torque of I·a/r holds the wheel there.
        let reapply = (recovery.max_accel_mps2 >= PEAK_LEARN_MIN_ACCEL_MPS2).then(|| {
            let torque_nm = WHEEL_INERTIA_KGM2 * recovery.max_accel_mps2 / WHEEL_RADIUS_M;
            let full_nm = BRAKE_TORQUE_AT_FULL_NM[ch.min(CHANNELS - 1)];
            REAPPLY_FRACTION * 100.0 * torque_nm / full_nm
        });
        self.recovery[ch] = None;
        if let Some(peak) = learned {
            // Stored so that the seek's present factor puts the target just below it.
            self.peak_slip[ch] = Some(peak / self.seek.scale);
        }
        Release::Ended(reapply)
    }

    /// The ABS release per wheel.
    fn abs(&mut self, now: Instant, v: f32, wheels: &[f32; 4], brake: f32, dt_s: f32) -> [f32; 4] {
        if self.variant == Variant::Faulty || brake <= BRAKING_THRESHOLD || v < ABS_MIN_SPEED_KMH {
            self.abs_off();
            self.reset_friction_estimate();
            return [0.0; 4];
        }
        self.update_friction_estimate(v, dt_s);
        let v = self.speed_reference(v, wheels, dt_s);
        let [fl, fr, rl, rr] = wheels.map(|w| (v - w) / v.max(SLIP_SPEED_FLOOR_KMH));
        // Select-low on the rear axle: the rear channel follows the wheel that slips more.
        let rear_wheel = if rr > rl { 3 } else { 2 };
        let channel_slip = [fl, fr, rl.max(rr)];
        let channel_wheel = [0, 1, rear_wheel];
        // Wheel accelerations ω̇·r, m/s².
        let accel = match self.previous_wheels_kmh {
            Some(previous) if dt_s > 0.0 => {
                core::array::from_fn(|i| (wheels[i] - previous[i]) / 3.6 / dt_s)
            }
            _ => [0.0f32; 4],
        };
        self.previous_wheels_kmh = Some(*wheels);
        let was_active = self.engaged.iter().any(|e| *e);
        let mut release = [0.0f32; CHANNELS];
        let mut acted = false;
        for ch in 0..CHANNELS {
            let slip = channel_slip[ch];
            if slip > SLIP_THRESHOLD {
                if !self.engaged[ch] {
                    // Pressure hold (crate documentation): release from the pressure
                    // built so far, not from the driver's command.
                    self.abs_pids[ch].set_integral(brake - self.pressure_estimate[ch]);
                }
                self.engaged[ch] = true;
                acted = true;
            }
            if !self.engaged[ch] {
                continue;
            }
            let phase = self.watch_recovery(ch, now, slip, accel[channel_wheel[ch]]);
            let target = self.slip_target(ch);
            let holding = phase == Release::Holding;
            let pid = &mut self.abs_pids[ch];
            if let Release::Ended(Some(reapply)) = phase {
                // Brake again at what the tyre was measured to carry (pressure memory).
                pid.set_integral(brake - limit(reapply, 0.0, brake));
            }
            // Reverse-acting loop: negating set point and measurement gives the error
            // `slip − target` and a derivative on +slip, so more slip means more release.
            let command = pid.update(-target, -slip, dt_s);
            if slip < target {
                // Under-braked: give the release back faster (see UNWIND_KI).
                pid.set_integral(pid.integral() + UNWIND_KI * (slip - target) * dt_s);
            }
            acted |= command >= RELEASE_ACTIVE_MIN || holding;
            if pid.integral() > brake || holding {
                // Anti-windup against the real limit: releasing more than the driver
                // brakes has no effect, so the integral holds at most the driver's command
                // (and all of it while the wheel spins back up).
                pid.set_integral(brake);
            }
            if holding {
                release[ch] = brake;
                continue;
            }
            if command >= brake && slip > RECOVERY_SLIP_FACTOR * target {
                // Released completely: watch the wheel spin back up for its peak.
                self.recovery[ch] = Some(Recovery {
                    since: now,
                    first_accel_mps2: None,
                    max_accel_mps2: 0.0,
                    slip_at_max: slip,
                });
            }
            // Releasing more than the driver brakes has no effect: report what acts.
            release[ch] = command.min(brake);
        }
        if acted {
            self.abs_last_acted = Some(now);
        }
        let timed_out = self
            .abs_last_acted
            .is_none_or(|t| now.micros_since(t) >= ABS_TIMEOUT_US);
        if timed_out {
            self.abs_off();
            return [0.0; 4];
        }
        if !was_active && self.engaged.iter().any(|e| *e) {
            autoplug_log::info!("abs: engaged at {} km/h", v);
        }
        let [r_fl, r_fr] = self.delay_yaw_moment([release[0], release[1]], brake, dt_s);
        let r_rear = release[2];
        // The brake torque all the brakes apply measures the force all the tyres transmit
        // (the drivetrain couples the wheels of the four-wheel drive, so one channel's
        // brake does not measure its own tyre alone).
        let mut regulating = self.engaged.iter().any(|e| *e);
        let mut torque = 0.0;
        for (ch, applied_release) in [r_fl, r_fr, r_rear].into_iter().enumerate() {
            // A channel counts while it regulates its wheel on its own: releasing, not
            // released completely, not held back by the yaw-moment limit.
            regulating &= !self.engaged[ch]
                || (self.recovery[ch].is_none()
                    && release[ch] >= RELEASE_ACTIVE_MIN
                    && applied_release == release[ch]);
            let wheels = if ch == 2 { 2.0 } else { 1.0 };
            torque += wheels * (brake - applied_release) * BRAKE_TORQUE_AT_FULL_NM[ch];
        }
        if regulating {
            self.seek.update(now, torque);
        } else {
            self.seek.restart();
        }
        [r_fl, r_fr, r_rear, r_rear]
    }

    /// Yaw-moment limit on the front axle (split friction): while the front axle is under
    /// ABS control, the front wheel braked harder may exceed the other's applied brake by
    /// at most a margin that grows slowly with time. On even friction both fronts brake
    /// alike and this does nothing; on split friction it keeps the high-friction side from
    /// yawing the car.
    fn delay_yaw_moment(&mut self, release: [f32; 2], brake: f32, dt_s: f32) -> [f32; 2] {
        if !(self.engaged[0] || self.engaged[1]) {
            self.yaw_delay_margin = None;
            return release;
        }
        let margin = match self.yaw_delay_margin {
            None => YAW_DELAY_INITIAL_MARGIN,
            Some(m) => (m + YAW_DELAY_MARGIN_RATE_PER_S * dt_s).min(100.0),
        };
        self.yaw_delay_margin = Some(margin);
        let applied = release.map(|r| brake - r);
        let (low, high) = if applied[0] <= applied[1] {
            (0, 1)
        } else {
            (1, 0)
        };
        let mut out = release;
        if applied[high] > applied[low] + margin {
            // Not `clamp(0.0, brake)`: that panics on a NaN or negative bound, and its
            // panic message alone pulls some 10 KiB of float formatting into the firmware.
            out[high] = (brake - (applied[low] + margin)).min(brake).max(0.0);
        }
        out
    }

    /// Disengages traction control: cut 0, controller reset.
    fn tc_off(&mut self) {
        self.tc_last_acted = None;
        self.tc_pid.reset();
    }

    /// The traction-control cut.
    fn traction(&mut self, now: Instant, v: f32, wheels: &[f32; 4], brake: f32, dt_s: f32) -> f32 {
        if brake > BRAKING_THRESHOLD {
            self.tc_off();
            return 0.0;
        }
        let reference = v.max(TC_SPEED_FLOOR_KMH);
        let mut worst = f32::MIN;
        let mut spinning = false;
        for w in wheels {
            let excess = w - v;
            let slip = excess / reference;
            spinning |= excess > TC_MIN_EXCESS_KMH && slip > TC_SLIP_THRESHOLD;
            worst = worst.max(slip);
        }
        if spinning && self.tc_last_acted.is_none() {
            autoplug_log::info!("abs: traction control at {} km/h", v);
            self.tc_last_acted = Some(now);
        }
        let Some(last_acted) = self.tc_last_acted else {
            return 0.0;
        };
        let cut = self.tc_pid.update(-TC_SLIP_TARGET, -worst, dt_s);
        if spinning || cut >= CUT_ACTIVE_MIN {
            self.tc_last_acted = Some(now);
        } else if now.micros_since(last_acted) >= TC_HOLD_US {
            self.tc_off();
            return 0.0;
        }
        cut
    }
}

impl EcuLogic for AbsEcu {
    type Sensors = Sensors;
    type Actuators = Actuators;

    const NODE: Node = Node::ABS;
    const STEP_PERIOD_US: u64 = STEP_PERIOD_US;

    fn on_frame(&mut self, now: Instant, frame: &Frame) {
        let released = self.pedal_brake.value().brake_cmd <= BRAKING_THRESHOLD;
        if !receive(&mut self.vehicle_speed, &mut self.dtcs, now, frame)
            && receive(&mut self.pedal_brake, &mut self.dtcs, now, frame)
        {
            // The driver starts braking: the pressure builds from this frame, not from
            // the next step (see `step_requested`).
            let onset = released && self.pedal_brake.value().brake_cmd > BRAKING_THRESHOLD;
            let spaced = self
                .last_onset
                .is_none_or(|t| now.micros_since(t) >= ONSET_STEP_MIN_GAP_US);
            if onset && spaced {
                self.brake_onset = true;
                self.last_onset = Some(now);
            }
        }
    }

    fn step_requested(&self) -> bool {
        self.brake_onset
    }

    fn step(&mut self, now: Instant, sensors: &Sensors) -> Actuators {
        let dt_s = match self.last_step {
            // Through u32 (71 minutes): a u64-to-float conversion is a library routine of
            // about 100 bytes on the Cortex-M4, a u32 one a single instruction.
            Some(last) => now.micros_since(last).min(u32::MAX.into()) as u32 as f32 * 1e-6,
            None => STEP_PERIOD_US as f32 * 1e-6,
        };
        self.last_step = Some(now);
        self.brake_onset = false;

        let speed_stale = supervise(&mut self.vehicle_speed, &mut self.dtcs, now);
        let pedal_stale = supervise(&mut self.pedal_brake, &mut self.dtcs, now);
        let (wheels, readings_valid) = self.check_wheel_sensors(now, &sensors.wheel_speed_kmh);
        self.wheels_turning = readings_valid && wheels.iter().any(|&w| w >= WHEEL_TURNING_KMH);
        let (brake, brake_source) = self.brake_command(now, pedal_stale, dt_s);
        let v = limit(
            self.vehicle_speed.value().vehicle_speed,
            0.0,
            WHEEL_SPEED_MAX_KMH,
        );

        let availability = if self.sensor_fault || !readings_valid {
            Availability::WheelSensorFault
        } else if speed_stale {
            Availability::NoSpeedReference
        } else {
            Availability::Available
        };
        let (release, cut) = if availability == Availability::Available {
            let release = self.abs(now, v, &wheels, brake, dt_s);
            let cut = self.traction(now, v, &wheels, brake, dt_s);
            (release, cut)
        } else {
            self.abs_off();
            self.reset_friction_estimate();
            self.tc_off();
            ([0.0; 4], 0.0)
        };
        let release = release.map(|r| limit(r, 0.0, 100.0));
        let cut = limit(cut, 0.0, 100.0);
        let [a, b, c, d] = release.map(|r| limit(brake - r, 0.0, brake));
        for (estimate, applied) in self.pressure_estimate.iter_mut().zip([a, b, c]) {
            let tau = if applied > *estimate {
                BRAKE_APPLY_TAU_S
            } else {
                BRAKE_RELEASE_TAU_S
            };
            *estimate += (applied - *estimate) * dt_s / (tau + dt_s);
        }

        self.status = Status {
            availability,
            brake_source,
            driver_brake: brake,
            release,
            brake: [a, b, c, d],
            abs_active: self.engaged.iter().any(|e| *e),
            slip_target: core::array::from_fn(|ch| self.slip_target(ch)),
            traction_active: self.tc_last_acted.is_some(),
            traction_cut: cut,
        };
        let [w_fl, w_fr, w_rl, w_rr] = wheels;
        let [r_fl, r_fr, r_rl, r_rr] = release;
        self.tx_wheels.set_message(&WheelSpeedMsg {
            wheel_speed_fl: w_fl,
            wheel_speed_fr: w_fr,
            wheel_speed_rl: w_rl,
            wheel_speed_rr: w_rr,
        });
        self.tx_abs.set_message(&AbsMsg {
            brake_fl: a,
            brake_fr: b,
            brake_rl: c,
            brake_rr: d,
            abs_release_fl: r_fl,
            abs_release_fr: r_fr,
            abs_release_rl: r_rl,
            abs_release_rr: r_rr,
        });
        self.tx_trac.set_message(&TracMsg { traction_cut: cut });
        Actuators {
            brake: [a, b, c, d],
        }
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        // Lowest identifier first: WheelSpeedMsg 0x00C, AbsMsg 0x00E, TracMsg 0x00F.
        self.tx_wheels
            .poll(now)
            .or_else(|| self.tx_abs.poll(now))
            .or_else(|| self.tx_trac.poll(now))
    }

    fn dtcs(&self) -> &Dtcs {
        &self.dtcs
    }

    fn dtcs_mut(&mut self) -> &mut Dtcs {
        &mut self.dtcs
    }

    fn own_sensors_show_motion(&self) -> bool {
        self.wheels_turning
    }
}

/// `x` limited to `[lo, hi]`, NaN to `lo`; never panics (unlike `f32::clamp`). Out of
/// line: inlined at each of its call sites it took 172 bytes more of the firmware.
#[inline(never)]
fn limit(x: f32, lo: f32, hi: f32) -> f32 {
    if x.is_nan() || x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

/// Test cases shared by the host and on-target suites.
#[cfg(any(test, feature = "test-cases"))]
pub mod test_cases;

#[cfg(test)]
mod tests;
