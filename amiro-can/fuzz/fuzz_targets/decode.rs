//! Coverage-guided fuzzing of the decoder: the first two bytes are the identifier, the rest the data.
//!
//! Checks what the ignored `fuzz_million` test checks, with libFuzzer steering towards new branches: no panic,
//! and every accepted frame re-encodes to a frame that decodes to the same message.
#![no_main]

use amiro_can::{decode, decode_command, DecodeError, Message};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|input: &[u8]| {
    let (id, data) = match input {
        [lo, hi, rest @ ..] => (u16::from_le_bytes([*lo, *hi]), rest),
        _ => return,
    };
    let result = decode(id, data);
    let command = decode_command(id, data);
    match result {
        Ok(message) => {
            let frame = message.encode();
            assert_eq!(frame.decode(), Ok(message));
            assert_eq!(message.try_encode(), Ok(frame));
            match message {
                Message::Command(c) => assert_eq!(command, Ok(c)),
                Message::Sample { .. } => assert!(matches!(command, Err(DecodeError::ExpectedCommand { .. }))),
            }
            // Display must not panic either.
            let _ = std::format!("{message}");
        }
        Err(e) => {
            assert!(e.kind_index() < DecodeError::KINDS.len());
            assert!(command.is_err());
            let _ = std::format!("{e}");
        }
    }
});
