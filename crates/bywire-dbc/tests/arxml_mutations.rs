//! ARXML files changed line by line (a line dropped, doubled, its numbers changed, its text
//! cut, the file ended early) are read leniently and strictly without a panic, and every frame
//! of what loads decodes, container frames split into their PDUs. The fuzz target
//! `database_formats` does the same with any bytes, for longer.
// Tests fail by panicking.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use bywire_core::{Frame, Id};
use bywire_dbc::decoder::Decoder;
use bywire_dbc::{format, Format, Mode};
use proptest::prelude::*;

const SYSTEM: &str = include_str!("../../../examples/data/powertrain.arxml");

/// `SYSTEM` with each change applied: (line, what, a number to use).
fn mutated(changes: &[(usize, u8, u32)]) -> String {
    let mut lines: Vec<String> = SYSTEM.lines().map(str::to_string).collect();
    for &(at, what, n) in changes {
        let at = at % lines.len();
        match what {
            0 => {
                lines.remove(at);
            }
            1 => lines.insert(at, lines[at].clone()),
            2 => {
                // Every number on the line replaced (sizes, identifiers, positions, lengths).
                let line: String = lines[at]
                    .split(|c: char| c.is_ascii_digit())
                    .collect::<Vec<_>>()
                    .join(&n.to_string());
                lines[at] = line;
            }
            3 => {
                let cut = (n as usize) % (lines[at].len() + 1);
                lines[at].truncate(cut);
            }
            _ => lines.truncate(at),
        }
        if lines.is_empty() {
            break;
        }
    }
    lines.join("\n")
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn changed_systems_never_panic(
        changes in prop::collection::vec((0usize..10_000, 0u8..5, any::<u32>()), 1..6),
        payload in prop::collection::vec(any::<u8>(), 0..64),
    ) {
        let text = mutated(&changes);
        let _ = format::load(text.as_bytes(), Format::Arxml, Mode::Strict);
        if let Ok((db, _)) = format::load(text.as_bytes(), Format::Arxml, Mode::Lenient) {
            let decoder = Decoder::new(db);
            for (index, m) in decoder.database().messages.iter().enumerate() {
                let id = if m.extended { Id::extended(m.id) } else { Id::standard(m.id) };
                let frame = Frame::fd(id.unwrap(), &payload, false, false);
                if let Ok(frame) = frame {
                    let _ = decoder.decode(&frame);
                }
                if let Some(pdus) = decoder.contained(index, &payload) {
                    for pdu in pdus.flatten() {
                        if let Some((_, codec, _)) = pdu.message {
                            let mut values = vec![None; codec.signal_count()];
                            let _ = codec.decode(pdu.pdu.data, &mut values);
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn the_example_system_loads_without_a_diagnostic() {
    let (db, diagnostics) = format::load(SYSTEM.as_bytes(), Format::Arxml, Mode::Strict).unwrap();
    assert!(diagnostics.is_empty(), "{diagnostics:?}");
    assert_eq!(db.messages.len(), 3);
    assert_eq!(db.containers[0].pdus.len(), 2);
}
