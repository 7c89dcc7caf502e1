//! Any text as a scenario file: reading never panics, a refusal names the file, and what is
//! accepted drives the simulated tug for a simulated second without a panic.
#![no_main]

use bywire_sim::scenario::Scenario;
use bywire_sim::tug::Tug;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let scenario = match Scenario::parse(text, "fuzz.toml") {
        Ok(scenario) => scenario,
        Err(e) => {
            assert!(e.to_string().starts_with("fuzz.toml"));
            return;
        }
    };
    let mut tug = Tug::new(scenario.params(1, scenario.tug.payload));
    for _ in 0..1_000 {
        scenario.step(&mut tug);
    }
});
