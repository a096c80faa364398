//! With the `log` backend, the macros reach whatever `log::Log` is installed, with the
//! level and the formatted message intact.

use std::sync::Mutex;

struct Capture(Mutex<Vec<(log::Level, String)>>);

impl log::Log for Capture {
    fn enabled(&self, _: &log::Metadata) -> bool {
        true
    }
    fn log(&self, record: &log::Record) {
        self.0
            .lock()
            .unwrap()
            .push((record.level(), record.args().to_string()));
    }
    fn flush(&self) {}
}

static CAPTURE: Capture = Capture(Mutex::new(Vec::new()));

#[test]
fn every_level_reaches_the_logger() {
    log::set_logger(&CAPTURE).unwrap();
    log::set_max_level(log::LevelFilter::Trace);
    assert_eq!(autoplug_log::BACKEND, "log");

    let speed = 88.5f32;
    autoplug_log::trace!("trace {}", 1);
    autoplug_log::debug!("debug {}", "two");
    autoplug_log::info!("cruise engaged at {} km/h", speed);
    autoplug_log::warn!("stale input {:?}", Some(3u8));
    autoplug_log::error!("dtc {}", 0x4A1u16);

    let got = CAPTURE.0.lock().unwrap().clone();
    assert_eq!(
        got,
        vec![
            (log::Level::Trace, "trace 1".to_string()),
            (log::Level::Debug, "debug two".to_string()),
            (log::Level::Info, "cruise engaged at 88.5 km/h".to_string()),
            (log::Level::Warn, "stale input Some(3)".to_string()),
            (log::Level::Error, "dtc 1185".to_string()),
        ]
    );
}
