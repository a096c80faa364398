//! A log as MCAP with every signal decoded, for the plotting tools engineers open directly
//! (Foxglove, Lichtblick, PlotJuggler): one JSON channel per catalogue message, named after
//! it (`/VehicleSpeedMsg`), whose fields are its signals in the DBC's units, with a JSON
//! schema and each signal's unit and COVESA VSS path in the channel's metadata; and one
//! channel of the raw frames (`/can/frames`: identifier, flags and data of every frame,
//! catalogue or not), so nothing of the log is lost. Times are the frames' own, in
//! nanoseconds. Written with Foxglove's `mcap` crate (zstd chunks).
//!
//! A frame of a catalogue identifier that does not decode (a wrong length, a value out of
//! range) goes to the raw channel only and is counted.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::{Seek, Write};

use autoplug_can::{Message, MESSAGES};
use mcap::records::MessageHeader;

use crate::frame::{FrameKind, LogFrame};
use crate::read::LogError;
use crate::write::{ExportError, ExportSummary};

/// The raw frames' topic.
pub const RAW_TOPIC: &str = "/can/frames";

/// What an MCAP export did, besides the frames written.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct McapSummary {
    /// Frames read and written to the raw channel, malformed lines skipped.
    pub export: ExportSummary,
    /// Catalogue frames decoded into their message's channel.
    pub decoded: u64,
    /// Catalogue frames that did not decode (raw channel only).
    pub undecodable: u64,
}

fn mcap_error(e: mcap::McapError) -> ExportError {
    ExportError::Write(std::io::Error::other(e.to_string()))
}

fn json_string(text: &str) -> String {
    // Signal and message names are DBC identifiers and VSS paths: no character needs more
    // than the two escapes JSON always needs.
    format!("\"{}\"", text.replace('\\', "\\\\").replace('"', "\\\""))
}

/// Converts a log (any reader of [`crate::read`]) to MCAP. Malformed lines are skipped and
/// counted; a fatal read error ends the input there (see [`ExportSummary::incomplete`]); a
/// write error stops it.
pub fn export_mcap<I, W>(frames: I, out: W) -> Result<McapSummary, ExportError>
where
    I: IntoIterator<Item = Result<LogFrame, LogError>>,
    W: Write + Seek,
{
    let mut writer = mcap::Writer::new(out).map_err(mcap_error)?;
    let raw_schema = writer
        .add_schema(
            "autoplug.CanFrame",
            "jsonschema",
            br#"{"type":"object","properties":{"id":{"type":"integer"},"extended":{"type":"boolean"},"kind":{"type":"string"},"channel":{"type":"integer"},"data":{"type":"array","items":{"type":"integer"}}}}"#,
        )
        .map_err(mcap_error)?;
    let raw_channel = writer
        .add_channel(raw_schema, RAW_TOPIC, "json", &BTreeMap::new())
        .map_err(mcap_error)?;
    let mut channels = Vec::with_capacity(MESSAGES.len());
    for spec in MESSAGES {
        let properties: Vec<String> = spec
            .signals
            .iter()
            .map(|s| {
                format!(
                    "{}:{{\"type\":\"number\",\"description\":{}}}",
                    json_string(s.name),
                    json_string(&format!("{} [{}]", s.vss, s.unit))
                )
            })
            .collect();
        let schema = format!(
            "{{\"type\":\"object\",\"title\":{},\"properties\":{{{}}}}}",
            json_string(spec.name),
            properties.join(",")
        );
        let schema_id = writer
            .add_schema(
                &format!("autoplug.{}", spec.name),
                "jsonschema",
                schema.as_bytes(),
            )
            .map_err(mcap_error)?;
        let mut metadata = BTreeMap::new();
        metadata.insert("can_id".to_string(), format!("0x{:03X}", spec.id));
        for s in spec.signals {
            metadata.insert(format!("{}.vss", s.name), s.vss.to_string());
            metadata.insert(format!("{}.unit", s.name), s.unit.to_string());
        }
        let topic = format!("/{}", spec.name);
        channels.push(
            writer
                .add_channel(schema_id, &topic, "json", &metadata)
                .map_err(mcap_error)?,
        );
    }

    let mut summary = McapSummary::default();
    let mut text = String::new();
    let mut sequence = 0u32;
    for item in frames {
        let frame = match item {
            Ok(frame) => frame,
            // What came before the damage is kept: the file is finished with it.
            Err(e) if e.is_fatal() => {
                summary.export.incomplete = Some(e);
                break;
            }
            Err(e) => {
                summary.export.skipped += 1;
                summary.export.first_skipped.get_or_insert(e);
                continue;
            }
        };
        let time_ns = frame.t_us.saturating_mul(1000);
        sequence = sequence.wrapping_add(1);
        let header = |channel_id| MessageHeader {
            channel_id,
            sequence,
            log_time: time_ns,
            publish_time: time_ns,
        };
        text.clear();
        let kind = match frame.kind {
            FrameKind::Data => "data",
            FrameKind::Remote => "remote",
            FrameKind::Error => "error",
        };
        let _ = write!(
            text,
            "{{\"id\":{},\"extended\":{},\"kind\":\"{kind}\",\"channel\":{},\"data\":{:?}}}",
            frame.id,
            frame.extended,
            frame.channel,
            frame.data()
        );
        writer
            .write_to_known_channel(&header(raw_channel), text.as_bytes())
            .map_err(mcap_error)?;
        summary.export.frames += 1;

        let Some(index) = (!frame.extended && frame.kind == FrameKind::Data)
            .then(|| MESSAGES.iter().position(|m| u32::from(m.id) == frame.id))
            .flatten()
        else {
            continue;
        };
        let spec = &MESSAGES[index];
        let Ok(message) = Message::decode(spec.id, frame.data()) else {
            summary.undecodable += 1;
            continue;
        };
        text.clear();
        text.push('{');
        for (i, s) in spec.signals.iter().enumerate() {
            let value = message.signal(i).unwrap_or(f32::NAN);
            if i > 0 {
                text.push(',');
            }
            // f32 values printed shortest-exact; never NaN for a decoded frame.
            let _ = write!(text, "{}:{}", json_string(s.name), value);
        }
        text.push('}');
        writer
            .write_to_known_channel(&header(channels[index]), text.as_bytes())
            .map_err(mcap_error)?;
        summary.decoded += 1;
    }
    writer.finish().map_err(mcap_error)?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoplug_can::{CanMessage, VehicleSpeedMsg};

    #[test]
    fn every_frame_raw_and_the_catalogue_decoded_readable_by_the_mcap_reader() {
        let speed = LogFrame::from_can(
            1_500_000,
            0,
            &VehicleSpeedMsg {
                vehicle_speed: 87.0,
            }
            .frame(),
        );
        let wrong_length =
            LogFrame::new(1_600_000, 0, 0x003, false, FrameKind::Data, &[1, 2]).unwrap();
        let unknown = LogFrame::new(1_700_000, 0, 0x123, false, FrameKind::Data, &[9]).unwrap();
        let frames = vec![
            Ok(speed),
            Err(LogError::at_line(2, "garbage")),
            Ok(wrong_length),
            Ok(unknown),
        ];
        let mut bytes = std::io::Cursor::new(Vec::new());
        let summary = export_mcap(frames, &mut bytes).unwrap();
        assert_eq!(
            (
                summary.export.frames,
                summary.export.skipped,
                summary.decoded,
                summary.undecodable
            ),
            (3, 1, 1, 1)
        );
        let bytes = bytes.into_inner();
        let messages: Vec<_> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .collect();
        let topics: Vec<&str> = messages.iter().map(|m| m.channel.topic.as_str()).collect();
        assert_eq!(
            topics,
            [RAW_TOPIC, "/VehicleSpeedMsg", RAW_TOPIC, RAW_TOPIC]
        );
        let decoded = &messages[1];
        assert_eq!(decoded.log_time, 1_500_000_000);
        assert_eq!(
            std::str::from_utf8(&decoded.data).unwrap(),
            "{\"VehicleSpeed\":87}"
        );
        assert_eq!(
            decoded
                .channel
                .metadata
                .get("VehicleSpeed.vss")
                .map(String::as_str),
            Some("Vehicle.Speed")
        );
        assert_eq!(
            std::str::from_utf8(&messages[3].data).unwrap(),
            "{\"id\":291,\"extended\":false,\"kind\":\"data\",\"channel\":0,\"data\":[9]}"
        );
    }
}
