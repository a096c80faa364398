//! The virtual car's socketcand server on whatever a client sends: the bytes arrive in the
//! chunks the input chooses, messages are cut out of the buffer and parsed. Nothing
//! panics, the buffer only shrinks when a message is taken, and every `send` accepted is a
//! valid classic CAN frame whose fields say what the text said.
#![no_main]

use autoplug_virtual_car::socketcand::{parse_command, take_message, Command};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // The first byte chooses the chunk size, as TCP would split the stream.
    let Some((&chunk, stream)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(chunk).max(1);
    let mut buffer = Vec::new();
    for piece in stream.chunks(chunk) {
        buffer.extend_from_slice(piece);
        loop {
            let before = buffer.len();
            let Some(message) = take_message(&mut buffer) else {
                break;
            };
            assert!(buffer.len() < before, "a message taken shrinks the buffer");
            assert!(!message.contains('>'), "a message ends at its first '>'");
            if let Ok(Command::Send(frame)) = parse_command(&message) {
                assert!(frame.id() <= 0x7FF && frame.len() <= 8);
                let words: Vec<&str> = message.split_whitespace().collect();
                assert_eq!(words[0], "send");
                assert_eq!(u32::from_str_radix(words[1], 16).ok(), Some(u32::from(frame.id())));
                assert_eq!(words[2].parse::<usize>().ok(), Some(frame.len()));
            }
        }
    }
});
