//! Decode a candump log with a DBC, printing each signal of each known frame.
//!
//!     cargo run -p bywire-examples --example decode_log -- vehicle.dbc drive.log
//!
//! Without arguments it decodes a few frames of the reference tug with its own DBC.

use std::io::BufRead;

use bywire_dbc::codec::MessageCodec;

const SAMPLE: &str = "(1700000000.000000) can0 100#640032000003B5A4\n\
                      (1700000000.020000) can0 101#6300320014000C63\n";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (dbc, log): (String, Box<dyn BufRead>) = match args.as_slice() {
        [dbc, log] => (
            std::fs::read_to_string(dbc)?,
            Box::new(std::io::BufReader::new(std::fs::File::open(log)?)),
        ),
        _ => (
            bywire_tug::messages::DBC.to_string(),
            Box::new(SAMPLE.as_bytes()),
        ),
    };
    // Lenient: what a reasonable engineer would accept loads, each problem reported.
    let (db, diagnostics) = bywire_dbc::parse_str(&dbc, bywire_dbc::Mode::Lenient)?;
    for d in &diagnostics {
        eprintln!("dbc: {d}");
    }
    let codecs: Vec<MessageCodec> = db.messages.iter().map(MessageCodec::new).collect();
    let mut values = vec![None; 64];
    for record in bywire_log::Reader::new(log) {
        let record = record?;
        let Some(id) = record.frame.id() else {
            continue;
        };
        let Some((message, codec)) = db
            .messages
            .iter()
            .zip(&codecs)
            .find(|(m, _)| m.id == id.as_raw() && m.extended == id.is_extended())
        else {
            continue;
        };
        values.resize(codec.signal_count(), None);
        codec.decode(record.frame.data(), &mut values)?;
        println!("{} {}", record.timestamp.as_nanos(), message.name);
        for (signal, value) in message.signals.iter().zip(&values) {
            if let Some(value) = value {
                println!(
                    "  {} = {} {}",
                    signal.name,
                    value.physical.as_f64(),
                    signal.unit
                );
            }
        }
    }
    Ok(())
}
