//! The UDS server fed arbitrary request sequences, physical and functional, in every
//! session and with security unlocked or not: it never panics, and every answer is a
//! positive response to the request's service or a three-byte negative response naming it.
#![no_main]

use autoplug_ecu::{Dtcs, Instant};
use autoplug_image::{BootState, Expectations, ImageSlot, Version, NUCLEO_F446RE};
use autoplug_uds::security::key_for;
use autoplug_uds::{Backend, Config, FlashError, Identification, Reply, Server};
use libfuzzer_sys::fuzz_target;

const SECTOR: usize = 128 * 1024;
const SECRET: &[u8] = b"fuzz secret";

struct Ecu {
    dfu: Vec<u8>,
    dtcs: Dtcs,
    speed: Option<f32>,
    /// Wrong keys in a row, as the flash keeps them.
    key_failures: u8,
}

impl Backend for Ecu {
    fn identification(&self) -> Identification<'_> {
        Identification {
            part_number: b"AP-FUZZ",
            software_version: b"1.0.0",
            serial_number: b"0001",
            hardware_version: b"NUCLEO-F446RE",
            vin: b"1AP0FUZZ3XX000001",
            boot_slot: Some((ImageSlot::A, BootState::Confirmed)),
        }
    }
    fn read_live_data(&mut self, did: u16, out: &mut [u8]) -> Option<usize> {
        (did == 0x0100 && !out.is_empty()).then(|| {
            out[0] = 1;
            1
        })
    }
    fn vehicle_speed_kmh(&self) -> Option<f32> {
        self.speed
    }
    fn dtcs(&mut self) -> &mut Dtcs {
        &mut self.dtcs
    }
    fn fill_random(&mut self, out: &mut [u8]) {
        out.fill(0x5A);
    }
    fn stored_key_failures(&mut self) -> u8 {
        self.key_failures
    }
    fn store_key_failures(&mut self, failures: u8) -> Result<(), FlashError> {
        self.key_failures = failures;
        Ok(())
    }
    fn image_expectations(&self) -> Expectations {
        Expectations {
            node: 0x0D,
            hardware_id: NUCLEO_F446RE,
            version_floor: Version::new(1, 0, 0),
            max_image_len: SECTOR as u32,
            load_address: ImageSlot::B.vector_table(),
            runs_machine_code: true,
        }
    }
    fn public_key(&self) -> [u8; 32] {
        [9; 32]
    }
    fn dfu_erase_steps(&self, len: u32) -> u32 {
        len.min(SECTOR as u32).div_ceil(SECTOR as u32)
    }
    fn dfu_erase(&mut self, step: u32) -> Result<(), FlashError> {
        let start = step as usize * SECTOR;
        self.dfu[start..start + SECTOR].fill(0xFF);
        Ok(())
    }
    fn dfu_write(&mut self, offset: u32, data: &[u8]) -> Result<(), FlashError> {
        let start = offset as usize;
        let cells = self
            .dfu
            .get_mut(start..start + data.len())
            .ok_or(FlashError)?;
        cells.copy_from_slice(data);
        Ok(())
    }
    fn dfu_read(&mut self, offset: u32, out: &mut [u8]) -> Result<(), FlashError> {
        let start = offset as usize;
        out.copy_from_slice(self.dfu.get(start..start + out.len()).ok_or(FlashError)?);
        Ok(())
    }
    fn mark_updated(&mut self) -> Result<(), FlashError> {
        Ok(())
    }
}

fuzz_target!(|data: &[u8]| {
    let mut ecu = Ecu {
        dfu: vec![0xFF; SECTOR],
        dtcs: Dtcs::new(),
        speed: Some(0.0),
        key_failures: 0,
    };
    let mut server = Server::new(Config::new(0x0D, SECRET), Instant::from_micros(0));
    let mut now = 0u64;
    let mut out = [0u8; 256];
    // The first byte's low bit: start unlocked in the programming session, erased, so the
    // download and check paths are reachable (the fuzzer cannot guess an HMAC key).
    let Some((&prelude, mut rest)) = data.split_first() else {
        return;
    };
    if prelude & 1 == 1 {
        let t = Instant::from_micros(0);
        server.handle(t, &[0x10, 0x02], false, &mut ecu, &mut out);
        let Reply::Send(n) = server.handle(t, &[0x27, 0x01], false, &mut ecu, &mut out) else {
            panic!("no seed");
        };
        let seed: [u8; 16] = out[2..n].try_into().expect("a 16-byte seed");
        let key = key_for(SECRET, 0x0D, &seed);
        let send = [&[0x27, 0x02][..], &key].concat();
        assert_eq!(
            server.handle(t, &send, false, &mut ecu, &mut out),
            Reply::Send(2)
        );
        let mut reply = server.handle(t, &[0x31, 0x01, 0xFF, 0x00], false, &mut ecu, &mut out);
        while matches!(reply, Reply::Pending(_) | Reply::Working) {
            reply = server.resume(t, &mut ecu, &mut out);
        }
        assert!(server.unlocked());
    }
    // Each request: a length byte, a flags byte (functional, time step), then the bytes.
    while let [len, flags, tail @ ..] = rest {
        let len = usize::from(*len).min(tail.len());
        let (request, next) = tail.split_at(len);
        rest = next;
        now += u64::from(flags >> 1) * 50_000;
        ecu.speed = if flags & 0x80 != 0 {
            Some(30.0)
        } else {
            Some(0.0)
        };
        server.poll(Instant::from_micros(now), &mut ecu);
        let functional = flags & 1 == 1;
        let mut reply = server.handle(
            Instant::from_micros(now),
            request,
            functional,
            &mut ecu,
            &mut out,
        );
        loop {
            match reply {
                Reply::Send(n) | Reply::SendThenReset(n, _) if n > 0 => {
                    let response = &out[..n];
                    let ok = response[0] == request[0].wrapping_add(0x40)
                        || (n == 3 && response[0] == 0x7F && response[1] == request[0]);
                    assert!(ok, "{request:02X?} -> {response:02X?}");
                    break;
                }
                Reply::Pending(_) | Reply::Working => {
                    reply = server.resume(Instant::from_micros(now), &mut ecu, &mut out);
                }
                _ => break,
            }
        }
        while server.program_step(&mut ecu, 64) {}
    }
});
