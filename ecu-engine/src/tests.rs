use crate::*;
use proptest::prelude::*;

proptest! {
    /// Any readings: the status stays within what EngineMsg carries and the frame sent
    /// decodes back to it within half a step.
    #[test]
    fn reports_within_limits(rpm in any::<f32>(), fuel in any::<f32>(), byte in any::<u8>()) {
        let mut ecu = EngineEcu::new(Instant::ZERO);
        ecu.on_frame(Instant::ZERO, &Frame::new(u32::from(AccMsg::ID), &[byte]).unwrap());
        let status = ecu.step(Instant::ZERO, &Sensors { engine_rpm: rpm, fuel_level_l: fuel, fuel_flow_l_per_h: 0.0 });
        prop_assert!((0.0..=ENGINE_RPM_MAX).contains(&status.engine_rpm));
        prop_assert!((0.0..=FUEL_LEVEL_MAX_L).contains(&status.fuel_level_l));
        let expected = if byte & 0b0100 != 0 { EngineMode::Economy } else { EngineMode::Sport };
        prop_assert_eq!(status.engine_mode, expected);
        let frame = ecu.poll_transmit(Instant::ZERO).unwrap();
        let msg = EngineMsg::decode(frame.data()).unwrap();
        prop_assert!((msg.engine_rpm - status.engine_rpm).abs() <= 18.0);
        prop_assert!((msg.fuel_level - status.fuel_level_l).abs() <= 0.125);
        prop_assert_eq!(msg.engine_mode, status.engine_mode);
    }
}

/// Engine off or idling lets the ECU be reprogrammed; above idle its own RPM vetoes,
/// whatever the bus says of the vehicle speed.
#[test]
fn rpm_above_idle_vetoes_programming() {
    let mut ecu = EngineEcu::new(Instant::ZERO);
    assert!(!ecu.own_sensors_show_motion(), "before the first step");
    let sensors = |engine_rpm| Sensors {
        engine_rpm,
        fuel_level_l: 30.0,
        fuel_flow_l_per_h: 0.0,
    };
    for (rpm, vetoes) in [
        (0.0, false),
        (850.0, false),
        (1200.0, false),
        (1201.0, true),
        (6000.0, true),
        (f32::NAN, false),
    ] {
        ecu.step(Instant::ZERO, &sensors(rpm));
        assert_eq!(ecu.own_sensors_show_motion(), vetoes, "{rpm} rpm");
    }
}
