//! What travels between the fleet and a vehicle for an update campaign: the instruction
//! the fleet signs (Uptane's director role in small: which image, for which ECU of which
//! vehicle, until when) and the vehicle's reports on it.
//!
//! The instruction is signed on top of the image's own signature, which the ECU checks:
//! the gateway acts only on an instruction signed by the fleet's key and meant for its
//! VIN, and only flashes the image the instruction names (its SHA-256, size, ECU and
//! version). Ed25519 with the same crate the images use; the key files are the same
//! format (`autoplug keygen`).
//!
//! On the wire the instruction is its JSON text inside an envelope with the signature over
//! exactly those bytes, so no re-encoding can change what was signed:
//! `{"instruction": "{\"campaign\":1,...}", "signature": "<128 hex digits>"}`.

use autoplug_image::SigningKey;
use autoplug_image::PUBLIC_KEY_LEN;
use serde::{Deserialize, Serialize};

/// Largest instruction envelope a vehicle reads, bytes.
pub const MAX_INSTRUCTION_BYTES: usize = 8 * 1024;

/// What the fleet tells one vehicle.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Instruction {
    /// Its number in the vehicle's series (1, 2, ...: every instruction for the vehicle
    /// gets the next): the vehicle refuses one not newer than the newest it has taken, so
    /// a captured instruction cannot be played to it again.
    pub number: u64,
    /// The campaign's number.
    pub campaign: i64,
    /// Its name.
    pub name: String,
    /// The vehicle it is for.
    pub vin: String,
    /// The ECU to update (`cruise`...).
    pub ecu: String,
    /// The image: SHA-256 of the whole signed file, lower-case hex.
    pub image_sha256: String,
    /// Its length, bytes.
    pub image_bytes: u64,
    /// The software version it carries.
    pub version: String,
    /// Which attempt for this vehicle (1, 2, ...).
    pub attempt: u32,
    /// When it was issued and until when it holds, ms since the Unix epoch.
    pub issued_at_ms: i64,
    /// See `issued_at_ms`.
    pub expires_at_ms: i64,
    /// What the driver is told (e.g. "fixes the cruise control's speed oscillation").
    pub message: String,
}

/// The signed form of an [`Instruction`] (see the module docs).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Envelope {
    /// The instruction's JSON text.
    pub instruction: String,
    /// Ed25519 over the bytes of `instruction`, hex.
    pub signature: String,
}

/// Why a vehicle does not act on an instruction.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum InstructionError {
    /// Not an envelope (not JSON, too large, fields missing).
    Malformed(String),
    /// The signature does not verify with the fleet's key: forged or altered.
    BadSignature,
    /// Signed, but for another vehicle.
    OtherVehicle(String),
    /// Signed, but expired.
    Expired,
}

impl std::fmt::Display for InstructionError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            InstructionError::Malformed(e) => write!(f, "not a campaign instruction: {e}"),
            InstructionError::BadSignature => f.write_str(
                "the instruction's signature does not verify with the fleet's key (forged or altered)",
            ),
            InstructionError::OtherVehicle(vin) => write!(f, "the instruction is for {vin}"),
            InstructionError::Expired => f.write_str("the instruction has expired"),
        }
    }
}

impl std::error::Error for InstructionError {}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex<const N: usize>(text: &str) -> Option<[u8; N]> {
    if text.len() != 2 * N || !text.is_ascii() {
        return None;
    }
    let mut out = [0u8; N];
    for (i, byte) in out.iter_mut().enumerate() {
        *byte = u8::from_str_radix(&text[2 * i..2 * i + 2], 16).ok()?;
    }
    Some(out)
}

/// Now, ms since the Unix epoch (the clock instructions and reports are stamped with).
pub fn now_ms() -> i64 {
    crate::unix_ms()
}

/// SHA-256 of `bytes`, lower-case hex (an image's name on the broker).
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    hex(&sha2::Sha256::digest(bytes))
}

impl Instruction {
    /// Signs it with the fleet's key: the envelope's JSON bytes.
    pub fn sign(&self, key: &SigningKey) -> Vec<u8> {
        let instruction = serde_json::to_string(self).unwrap_or_default();
        let signature = hex(&key.sign(instruction.as_bytes()));
        serde_json::to_vec(&Envelope {
            instruction,
            signature,
        })
        .unwrap_or_default()
    }

    /// Reads an envelope: verifies its signature with `fleet_key`, then that it is for
    /// `vin` and has not expired at `now_ms`. Nothing of the instruction is trusted before
    /// the signature verified.
    pub fn open(
        payload: &[u8],
        fleet_key: &[u8; PUBLIC_KEY_LEN],
        vin: &str,
        now_ms: i64,
    ) -> Result<Instruction, InstructionError> {
        if payload.len() > MAX_INSTRUCTION_BYTES {
            return Err(InstructionError::Malformed(format!(
                "{} bytes (at most {MAX_INSTRUCTION_BYTES})",
                payload.len()
            )));
        }
        let envelope: Envelope = serde_json::from_slice(payload)
            .map_err(|e| InstructionError::Malformed(e.to_string()))?;
        let signature = unhex::<64>(&envelope.signature).ok_or_else(|| {
            InstructionError::Malformed("the signature is not 128 hex digits".into())
        })?;
        let key =
            salty::PublicKey::try_from(fleet_key).map_err(|_| InstructionError::BadSignature)?;
        key.verify(
            envelope.instruction.as_bytes(),
            &salty::Signature::from(&signature),
        )
        .map_err(|_| InstructionError::BadSignature)?;
        let instruction: Instruction = serde_json::from_str(&envelope.instruction)
            .map_err(|e| InstructionError::Malformed(e.to_string()))?;
        if instruction.vin != vin {
            return Err(InstructionError::OtherVehicle(instruction.vin));
        }
        if now_ms > instruction.expires_at_ms {
            return Err(InstructionError::Expired);
        }
        Ok(instruction)
    }
}

/// Where a vehicle stands in a campaign.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VehicleState {
    /// Targeted, no instruction sent yet (its stage has not come).
    Waiting,
    /// The instruction went to the broker.
    Sent,
    /// The vehicle checked the instruction and the image and asked its driver.
    Received,
    /// The driver agreed; flashing (or waiting for the car to stand still).
    Installing,
    /// Flashed; the ECU runs the new version.
    Installed,
    /// The driver declined.
    Declined,
    /// The vehicle refused: the instruction or the image did not check (the reason says
    /// which), or the ECU refused the image.
    Refused,
    /// The flash failed; the ECU runs its old software.
    Failed,
    /// No answer within the campaign's time, after the last attempt.
    NoAnswer,
}

impl VehicleState {
    /// Every state, in the order a vehicle goes through them.
    pub const ALL: [VehicleState; 9] = [
        VehicleState::Waiting,
        VehicleState::Sent,
        VehicleState::Received,
        VehicleState::Installing,
        VehicleState::Installed,
        VehicleState::Declined,
        VehicleState::Refused,
        VehicleState::Failed,
        VehicleState::NoAnswer,
    ];

    /// Its name in the database and on the wire.
    pub fn name(self) -> &'static str {
        match self {
            VehicleState::Waiting => "waiting",
            VehicleState::Sent => "sent",
            VehicleState::Received => "received",
            VehicleState::Installing => "installing",
            VehicleState::Installed => "installed",
            VehicleState::Declined => "declined",
            VehicleState::Refused => "refused",
            VehicleState::Failed => "failed",
            VehicleState::NoAnswer => "no_answer",
        }
    }

    /// The state of a name.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// Whether the vehicle is done with this attempt (the fleet decides about another).
    pub fn is_final(self) -> bool {
        matches!(
            self,
            VehicleState::Installed
                | VehicleState::Declined
                | VehicleState::Refused
                | VehicleState::Failed
                | VehicleState::NoAnswer
        )
    }

    /// Whether it counts against the stage's failure threshold.
    pub fn is_failure(self) -> bool {
        matches!(self, VehicleState::Refused | VehicleState::Failed)
    }
}

/// A vehicle's report on a campaign.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct CampaignReport {
    /// The vehicle.
    pub vin: String,
    /// The campaign.
    pub campaign: i64,
    /// The attempt the report answers.
    pub attempt: u32,
    /// Where it stands: received, installing, installed, declined, refused or failed.
    pub state: VehicleState,
    /// Why (a refusal's or a failure's reason).
    pub reason: Option<String>,
    /// The ECU.
    pub ecu: String,
    /// The software version the ECU runs now, as it answered (F189).
    pub version_running: Option<String>,
    /// When, ms since the Unix epoch (the vehicle's clock).
    pub at_ms: i64,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn instruction() -> Instruction {
        Instruction {
            number: 3,
            campaign: 7,
            name: "cruise-1.2.0".into(),
            vin: "JA3AP47H0YF000042".into(),
            ecu: "cruise".into(),
            image_sha256: sha256_hex(b"image"),
            image_bytes: 5,
            version: "1.2.0".into(),
            attempt: 1,
            issued_at_ms: 1_000,
            expires_at_ms: 10_000,
            message: "fixes the speed oscillation".into(),
        }
    }

    #[test]
    fn a_signed_instruction_opens_only_with_the_fleet_key_for_its_vehicle_in_time() {
        let key = SigningKey::from_seed([7; 32]);
        let other = SigningKey::from_seed([8; 32]);
        let signed = instruction().sign(&key);
        let vin = "JA3AP47H0YF000042";
        assert_eq!(
            Instruction::open(&signed, &key.public_key(), vin, 2_000),
            Ok(instruction())
        );
        // Another key: forged.
        assert_eq!(
            Instruction::open(&signed, &other.public_key(), vin, 2_000),
            Err(InstructionError::BadSignature)
        );
        // Altered after signing: the ECU changed inside the signed text.
        let mut envelope: Envelope = serde_json::from_slice(&signed).unwrap();
        envelope.instruction = envelope.instruction.replace("\"cruise\"", "\"abs\"");
        let altered = serde_json::to_vec(&envelope).unwrap();
        assert_eq!(
            Instruction::open(&altered, &key.public_key(), vin, 2_000),
            Err(InstructionError::BadSignature)
        );
        // Signed by the fleet, but for another vehicle, or expired.
        assert_eq!(
            Instruction::open(&signed, &key.public_key(), "JA3AP47H2YF000043", 2_000),
            Err(InstructionError::OtherVehicle(vin.into()))
        );
        assert_eq!(
            Instruction::open(&signed, &key.public_key(), vin, 10_001),
            Err(InstructionError::Expired)
        );
        // Not an envelope at all.
        for junk in [
            &b"{"[..],
            b"[]",
            b"{\"instruction\":\"x\",\"signature\":\"zz\"}",
        ] {
            assert!(matches!(
                Instruction::open(junk, &key.public_key(), vin, 2_000),
                Err(InstructionError::Malformed(_))
            ));
        }
        assert!(matches!(
            Instruction::open(
                &vec![b' '; MAX_INSTRUCTION_BYTES + 1],
                &key.public_key(),
                vin,
                0
            ),
            Err(InstructionError::Malformed(_))
        ));
    }

    #[test]
    fn states_round_trip_by_name() {
        for s in VehicleState::ALL {
            assert_eq!(VehicleState::parse(s.name()), Some(s));
            assert_eq!(
                serde_json::to_string(&s).unwrap(),
                format!("\"{}\"", s.name())
            );
        }
        assert_eq!(VehicleState::parse("done"), None);
    }
}
