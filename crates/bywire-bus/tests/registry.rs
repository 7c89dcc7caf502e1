//! A backend from outside the crate, added by scheme: its specs parse, open, listen and list
//! like the built-in ones, and what it refuses is said as it says it.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::time::Duration;

use bywire_bus::virtual_bus::VirtualBus;
use bywire_bus::{
    is_in_process, open, open_listening, register, schemes, Backend, Bus, BusSpec, Listening,
    OpenError, RegisterError, SpecError,
};

/// `loop:NAME`: an in-process bus under another name (what a third-party crate would write
/// for its adapter).
struct Loop;

impl Backend for Loop {
    fn check(&self, parameters: &str) -> Result<(), String> {
        match parameters.is_empty() {
            true => Err("no bus name".into()),
            false => Ok(()),
        }
    }
    fn open(&self, parameters: &str) -> Result<Box<dyn Bus>, String> {
        match parameters {
            "broken" => Err("the adapter is unplugged".into()),
            name => Ok(Box::new(VirtualBus::join(&format!("loop-{name}")))),
        }
    }
    fn in_process(&self) -> bool {
        true
    }
}

/// `far:NAME`: the defaults (not in process, no listen-only mode).
struct Far;

impl Backend for Far {
    fn check(&self, _: &str) -> Result<(), String> {
        Ok(())
    }
    fn open(&self, parameters: &str) -> Result<Box<dyn Bus>, String> {
        Ok(Box::new(VirtualBus::join(&format!("far-{parameters}"))))
    }
}

#[test]
fn a_registered_backend_is_a_scheme_like_the_built_in_ones() {
    // Unknown before it is registered.
    let before = "loop:a".parse::<BusSpec>().unwrap_err();
    assert!(
        matches!(before, SpecError::UnknownScheme { .. }),
        "{before}"
    );
    register("loop", Loop).unwrap();
    register("far", Far).unwrap();
    assert_eq!(
        register("loop", Far),
        Err(RegisterError::Taken("loop".into()))
    );
    assert_eq!(
        register("socketcan", Far),
        Err(RegisterError::Taken("socketcan".into()))
    );
    for bad in ["", "Loop", "9p", "a b", "lo:op"] {
        assert_eq!(
            register(bad, Far),
            Err(RegisterError::BadScheme(bad.into()))
        );
    }
    let known = schemes();
    assert!(
        known.starts_with(&["virtual".to_string(), "sim".to_string()]),
        "{known:?}"
    );
    assert!(known.contains(&"loop".to_string()) && known.contains(&"far".to_string()));
    let unknown = "carrier:pigeon".parse::<BusSpec>().unwrap_err().to_string();
    assert!(unknown.contains("far, loop"), "{unknown}");

    // Parsed, checked by its backend, written back as typed.
    let spec: BusSpec = "loop:a".parse().unwrap();
    assert_eq!(spec.to_string(), "loop:a");
    let refused = "loop:".parse::<BusSpec>().unwrap_err();
    assert_eq!(refused.to_string(), "loop: no bus name");

    // Opened: two endpoints of loop:a hear each other.
    let mut a = open("loop:a").unwrap();
    let mut b = open("loop:a").unwrap();
    a.send(&"123#BEEF".parse().unwrap()).unwrap();
    let got = b.recv(Some(Duration::from_secs(5))).unwrap().unwrap();
    assert_eq!(got.frame.to_string(), "123#BEEF");
    match open("loop:broken") {
        Err(OpenError::Refused { spec, reason }) => {
            assert_eq!(
                (spec.as_str(), reason.as_str()),
                ("loop:broken", "the adapter is unplugged")
            );
        }
        Err(other) => panic!("{other}"),
        Ok(_) => panic!("an unplugged adapter opened"),
    }

    // Listening and in-process, as each backend says (or by default).
    assert!(is_in_process("loop:a"));
    assert!(!is_in_process("far:a"));
    let (_, how) = open_listening("far:a").unwrap();
    assert!(matches!(how, Listening::NotListenOnly(_)), "{how:?}");
}
