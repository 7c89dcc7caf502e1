//! The secured variant end to end: the ADS side and the supervisor over the tug's wire, with
//! an attacker's frames between them — forged, replayed, a restarted sender's rewind, its
//! resynchronisation, and a restart from a persisted freshness.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)]

use bywire_core::node::{Node, Port};
use bywire_core::{Frame, Id, Timestamp};
use bywire_secoc::store::FreshnessStore;
use bywire_secoc::Key;
use bywire_tug::messages::{self, AdsToVehicleControl, ControlMode, EmergencyStop, Gear};
use bywire_tug::secured::{self, TugWire, SECURED, WINDOW};
use bywire_vehicle::ads::{Ads, AdsCommand, AdsConfig};
use bywire_vehicle::supervisor::{EstopState, Supervisor, SupervisorConfig};

const KEY: [u8; 16] = [0x42; 16];

fn ms(t: u64) -> Timestamp {
    Timestamp::from_millis(t)
}

fn drive() -> AdsCommand {
    AdsCommand {
        velocity: 2.0,
        steering: 4.0,
        gear: Gear::Drive,
        mode: ControlMode::Autonomous,
        ..AdsCommand::default()
    }
}

fn wire(next: u64) -> TugWire {
    secured::secured(&Key::new(KEY), next).unwrap()
}

fn command_id() -> Id {
    Id::standard(AdsToVehicleControl::ID).unwrap()
}

/// The ADS side and the supervisor on one bus, a millisecond at a time: what the ADS sends
/// goes to the supervisor with what `tamper` adds after it, and the supervisor's frames back.
struct Bench {
    ads: Ads<TugWire>,
    supervisor: Supervisor<TugWire>,
    now: u64,
    /// The commands as they went on the wire.
    commands: Vec<Frame>,
}

impl Bench {
    fn new(ads: TugWire, vehicle: TugWire) -> Bench {
        Bench {
            ads: Ads::with_wire(AdsConfig::default(), ads),
            supervisor: Supervisor::with_wire(SupervisorConfig::default(), vehicle),
            now: 0,
            commands: Vec::new(),
        }
    }

    fn run(&mut self, millis: u64, tamper: &mut dyn FnMut(&Frame) -> Vec<Frame>) {
        self.run_in_steps(millis, 1, tamper);
    }

    /// `steps` turns `step` ms apart.
    fn run_in_steps(
        &mut self,
        steps: u64,
        step: u64,
        tamper: &mut dyn FnMut(&Frame) -> Vec<Frame>,
    ) {
        for _ in 0..steps {
            let now = ms(self.now);
            self.ads.set_command(now, drive());
            let mut to_vehicle = Vec::new();
            self.ads.poll(now, &mut |port, f| {
                if port == Port::MAIN {
                    to_vehicle.push(f)
                }
            });
            for frame in to_vehicle {
                let added = if frame.id() == Some(command_id()) {
                    self.commands.push(frame);
                    tamper(&frame)
                } else {
                    Vec::new()
                };
                for f in std::iter::once(frame).chain(added) {
                    self.supervisor.on_frame(now, Port::MAIN, &f);
                }
            }
            let mut to_ads = Vec::new();
            self.supervisor.poll(now, &mut |port, f| {
                if port == Port::MAIN {
                    to_ads.push(f)
                }
            });
            for frame in to_ads {
                self.ads.on_frame(now, Port::MAIN, &frame);
            }
            self.now += step;
        }
    }

    fn quiet(&mut self, millis: u64) {
        self.run(millis, &mut |_| Vec::new());
    }

    /// Drive for `seconds` of simulated time in 10 ms steps (the command cycle is 20 ms).
    fn drive_for(&mut self, seconds: u64) {
        self.run_in_steps(seconds * 100, 10, &mut |_| Vec::new());
    }
}

/// The attacker's command: the genuine one's next counter, a valid CRC, steering 30°.
fn forged_after(genuine: &Frame) -> Frame {
    let payload: [u8; 8] = genuine.data()[..8].try_into().unwrap();
    let m = AdsToVehicleControl(payload);
    let mut command = messages::command_of(&m).unwrap();
    command.steering = 30.0;
    let counter = u8::try_from((m.heartbeat_counter_raw() + 1) & 0x0F).unwrap();
    messages::sealed_frame(
        AdsToVehicleControl::ID,
        messages::command_message(&command, counter).unwrap().0,
    )
}

#[test]
fn without_secoc_a_forged_command_with_valid_crc_and_counter_is_obeyed() {
    // The reason to enable SecOC: CRC and counter are public, so the forgery passes both.
    let mut bench = Bench::new(secured::plain(), secured::plain());
    bench.quiet(200);
    bench.run(200, &mut |f| vec![forged_after(f)]);
    let stats = bench.supervisor.stats();
    assert!(stats.accepted >= 20, "{stats:?}");
    assert_eq!(bench.supervisor.command().map(|c| c.steering), Some(30.0));
    // The ADS's own commands are the ones refused, as repeats of the forged counters.
    assert!(stats.repeated >= 9, "{stats:?}");
}

/// Verifies: REQ-SEC-1.
#[test]
fn with_secoc_forged_commands_are_refused_and_counted_and_the_genuine_ones_obeyed() {
    let mut bench = Bench::new(wire(1), wire(1));
    bench.quiet(200);
    let before = bench.supervisor.stats();
    // Classic forgeries, and forgeries in the secured shape with the last MAC seen.
    bench.run(200, &mut |genuine| {
        let forged = forged_after(genuine);
        let mut shaped = genuine.data().to_vec();
        shaped[..8].copy_from_slice(forged.data());
        shaped[8] = shaped[8].wrapping_add(1);
        let shaped = Frame::fd(genuine.id().unwrap(), &shaped, true, false).unwrap();
        vec![forged, shaped]
    });
    let stats = bench.supervisor.stats();
    let cycles = 10;
    assert_eq!(
        stats.authentication - before.authentication,
        2 * cycles,
        "{stats:?}"
    );
    assert_eq!(stats.accepted - before.accepted, cycles, "{stats:?}");
    assert_eq!(stats.repeated, 0);
    assert_eq!(bench.supervisor.command().map(|c| c.steering), Some(4.0));
    let verified = bench.supervisor.wire().table().unwrap().stats().frames;
    assert_eq!((verified.mac, verified.malformed), (cycles, cycles));
}

/// Verifies: REQ-SEC-1.
#[test]
fn with_secoc_a_replayed_command_is_refused_as_stale() {
    let mut bench = Bench::new(wire(1), wire(1));
    bench.quiet(200);
    let captured = bench.commands.clone();
    // Each replayed frame is authentic, with its original counter and CRC: only its
    // freshness gives it away.
    let mut replay = captured.into_iter();
    bench.run(200, &mut |_| replay.next().into_iter().collect());
    let stats = bench.supervisor.stats();
    assert_eq!(stats.authentication, 10, "{stats:?}");
    let verified = bench.supervisor.wire().table().unwrap().stats().frames;
    assert_eq!(verified.stale, 10, "{verified:?}");
    assert_eq!(bench.supervisor.command().map(|c| c.steering), Some(4.0));
}

#[test]
fn a_restart_without_the_freshness_is_a_rewind_refused_until_the_vehicle_resynchronises_it() {
    let mut bench = Bench::new(wire(1), wire(1));
    bench.quiet(400);
    assert_eq!(bench.supervisor.stats().accepted, 20);
    // The ADS restarts and counts from 1 again: its frames carry values already used.
    bench.ads = Ads::with_wire(AdsConfig::default(), wire(1));
    bench.quiet(60);
    let stats = bench.supervisor.stats();
    assert!(stats.authentication >= 1, "{stats:?}");
    let vehicle = bench.supervisor.wire().table().unwrap().stats();
    assert!(
        vehicle.frames.stale >= 1 && vehicle.syncs_sent == 1,
        "{vehicle:?}"
    );
    // The sync went out at once; the ADS took it and goes on after the last accepted value.
    let ads = bench.ads.wire().table().unwrap().stats();
    assert_eq!(ads.syncs_taken, 1, "{ads:?}");
    let (refused, accepted) = (stats.authentication, stats.accepted);
    bench.quiet(200);
    let stats = bench.supervisor.stats();
    assert_eq!(stats.authentication, refused, "no more refusals: {stats:?}");
    assert_eq!(stats.accepted - accepted, 10);
}

/// A restart without the freshness store after 1 s, 1 min and 1 h of driving: the first
/// command is accepted again within 0.5 s, whatever the gap. Before, a sender more than two
/// wraps of its 8 sent bits behind (about 10 s at 50 Hz) had its frames counted as forged,
/// no sync was sent, and the vehicle refused it until its freshness caught up (as long as it
/// had driven).
#[test]
fn a_restart_without_the_store_is_resynchronised_within_half_a_second_whatever_the_gap() {
    for seconds in [1, 60, 3600] {
        let mut bench = Bench::new(wire(1), wire(1));
        bench.drive_for(seconds);
        let before = bench.supervisor.stats();
        assert!(before.accepted >= seconds * 49, "{seconds} s: {before:?}");
        bench.ads = Ads::with_wire(AdsConfig::default(), wire(1));
        let restart = bench.now;
        let mut accepted_at = None;
        for _ in 0..1000 {
            bench.quiet(1);
            if bench.supervisor.stats().accepted > before.accepted {
                accepted_at = Some(bench.now - restart);
                break;
            }
        }
        let after = bench.supervisor.stats();
        let vehicle = bench.supervisor.wire().table().unwrap().stats();
        let taken = accepted_at.unwrap_or_else(|| panic!("{seconds} s: {after:?} {vehicle:?}"));
        assert!(
            taken <= 500,
            "{seconds} s: accepted {taken} ms after the restart"
        );
        assert!(vehicle.syncs_sent >= 1, "{vehicle:?}");
        // The restarted ADS goes on after every value used before its restart.
        let ads_next = bench
            .ads
            .wire()
            .table()
            .unwrap()
            .next_freshness(command_id());
        assert!(
            ads_next.unwrap() > seconds * 49,
            "{seconds} s: {ads_next:?}"
        );
    }
}

#[test]
fn a_sync_from_another_key_is_never_taken() {
    let mut bench = Bench::new(wire(1), wire(1));
    bench.quiet(100);
    // A vehicle with another key refuses the ADS's frames as forged.
    let mut other = Supervisor::with_wire(
        SupervisorConfig::default(),
        secured::secured(&Key::new([7; 16]), 1).unwrap(),
    );
    let old = bench.commands[0];
    other.on_frame(ms(100), Port::MAIN, &old);
    let mut sent = Vec::new();
    other.poll(ms(100), &mut |port, f| {
        if port == Port::MAIN {
            sent.push(f)
        }
    });
    assert_eq!(other.wire().table().unwrap().stats().frames.mac, 1);
    // It answers with a sync, as to any frame behind: signed with its key (refused below).
    assert!(sent
        .iter()
        .any(|f| f.id().map(Id::as_raw) == Some(secured::SYNC_ID)));
    // A sync signed with another key, to the real ADS: refused, the freshness unmoved.
    let mut stale = Supervisor::with_wire(
        SupervisorConfig::default(),
        secured::secured(&Key::new([7; 16]), 1).unwrap(),
    );
    let mut liar_ads = Ads::with_wire(
        AdsConfig::default(),
        secured::secured(&Key::new([7; 16]), 1).unwrap(),
    );
    let mut frames = Vec::new();
    for t in 0..100 {
        liar_ads.set_command(ms(t), drive());
        liar_ads.poll(ms(t), &mut |port, f| {
            if port == Port::MAIN {
                frames.push(f)
            }
        });
    }
    for f in frames.iter().chain(frames.iter()) {
        stale.on_frame(ms(100), Port::MAIN, f);
    }
    let mut sync = Vec::new();
    stale.poll(ms(100), &mut |port, f| {
        if port == Port::MAIN {
            sync.push(f)
        }
    });
    let sync = sync
        .into_iter()
        .find(|f| f.id().map(Id::as_raw) == Some(secured::SYNC_ID))
        .unwrap();
    let next = bench
        .ads
        .wire()
        .table()
        .unwrap()
        .next_freshness(command_id());
    bench.ads.on_frame(ms(100), Port::MAIN, &sync);
    let ads = bench.ads.wire().table().unwrap();
    assert_eq!(ads.stats().syncs_refused, 1);
    assert_eq!(ads.next_freshness(command_id()), next);
}

#[test]
fn a_restart_from_the_persisted_freshness_is_accepted_at_once() {
    let dir = std::env::temp_dir().join(format!("bywire-secured-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("ads.freshness");
    let _ = std::fs::remove_file(&path);
    // The store reserves no more ahead than the receivers' window allows.
    let step = WINDOW / 4;
    let (mut store, start) = FreshnessStore::open(&path, step).unwrap();
    let mut bench = Bench::new(wire(start), wire(1));
    for _ in 0..40 {
        let next = bench
            .ads
            .wire()
            .table()
            .unwrap()
            .next_freshness(command_id())
            .unwrap();
        store.before_signing(next).unwrap();
        bench.quiet(20);
    }
    assert_eq!(bench.supervisor.stats().accepted, 40);
    drop(store);
    let (_, start) = FreshnessStore::open(&path, step).unwrap();
    assert!(start > 40 && start <= 40 + step + 1, "{start}");
    bench.ads = Ads::with_wire(AdsConfig::default(), wire(start));
    bench.quiet(200);
    let stats = bench.supervisor.stats();
    // Every frame authentic; the restarted ADS's rolling counter starts over, and its first
    // frame is refused for that alone (a skipped counter), as without SecOC.
    assert_eq!(
        (stats.accepted, stats.skipped, stats.authentication),
        (49, 1, 0),
        "{stats:?}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_secured_estop_forged_classic_is_refused_and_not_read() {
    let mut bench = Bench::new(wire(1), wire(1));
    bench.quiet(100);
    // The E-stop message forged classic with a valid CRC, "closed": counted, not read.
    let mut m = EmergencyStop::default();
    m.set_estop_request_raw(0);
    let forged = messages::sealed_frame(EmergencyStop::ID, m.0);
    bench.supervisor.on_frame(ms(100), Port::MAIN, &forged);
    assert_eq!(bench.supervisor.stats().unauthenticated, 1);
    assert!(SECURED.contains(&EmergencyStop::ID));
}

#[test]
fn an_estop_chain_heard_once_and_then_silent_is_open() {
    let mut bench = Bench::new(secured::plain(), secured::plain());
    let mut m = EmergencyStop::default();
    m.set_estop_request_raw(0);
    let closed = messages::sealed_frame(EmergencyStop::ID, m.0);
    bench.supervisor.on_frame(ms(0), Port::MAIN, &closed);
    // Three cycles of 20 ms without the chain's frame: it counts as open.
    bench.quiet(59);
    assert_eq!(bench.supervisor.estop(), EstopState::Normal);
    bench.quiet(10);
    assert!(bench.supervisor.estop().is_latched());
}

/// The tug's profile with a `[secoc]` section declaring what `bywire_tug::secured` builds in.
fn secured_profile(extra: &str) -> Result<bywire_vehicle::profile::LoadedProfile, String> {
    let text = format!(
        "{}\n[secoc]\nmessages = [\"AdsToVehicle_Control\", \"EmergencyBrake\", \"EmergencyStop\", \"VehicleToAds_State\", \"VehicleToAds_Sensors\", \"VehicleToAds_WheelAngles\"]\n{extra}",
        bywire_tug::PROFILE
    );
    bywire_vehicle::profile::Profile::parse("secured-tug", &text, |_| Ok(messages::DBC.to_string()))
        .map_err(|e| e.to_string())
}

fn key_file() -> bywire_secoc::keys::KeyFile {
    let hex: String = KEY.iter().map(|b| format!("{b:02x}")).collect();
    bywire_secoc::keys::KeyFile::parse(std::path::Path::new("k"), format!("3 {hex}\n").as_bytes())
        .unwrap()
}

#[test]
fn a_profile_declaring_secoc_makes_the_same_frames_as_the_built_in_variant() {
    let lengths =
        "fv_length = 64\nfv_tx_length = 8\nmac_tx_length = 24\nkey_id = 3\nsync_id = 0x0F0\n";
    let loaded = secured_profile(lengths).unwrap();
    let mut by_profile = loaded.secured_wire(&key_file(), 77).unwrap();
    let mut built_in = wire(77);
    use bywire_vehicle::wire::AdsWire;
    for k in 0..20u64 {
        let command = AdsCommand {
            steering: k as f64 - 10.0,
            ..drive()
        };
        let a = by_profile.command_frame(&command, k).unwrap();
        let b = built_in.command_frame(&command, k).unwrap();
        assert_eq!(a, b, "command {k}");
        assert!(a.is_fd() && a.data().len() == 12);
    }
    // And the two read each other's frames: a supervisor over the profile's wire takes the
    // built-in ADS's commands, refuses a forgery.
    let vehicle = loaded.secured_wire(&key_file(), 1).unwrap();
    let mut supervisor = Supervisor::with_wire(SupervisorConfig::default(), vehicle);
    let mut ads = Ads::with_wire(AdsConfig::default(), wire(1));
    for t in 0..200 {
        ads.set_command(ms(t), drive());
        let mut frames = Vec::new();
        ads.poll(ms(t), &mut |port, f| {
            if port == Port::MAIN {
                frames.push(f)
            }
        });
        for f in frames {
            supervisor.on_frame(ms(t), Port::MAIN, &f);
            supervisor.on_frame(ms(t), Port::MAIN, &forged_after(&f));
        }
        supervisor.poll(ms(t), &mut |_, _| {});
    }
    let stats = supervisor.stats();
    assert_eq!(
        (stats.accepted, stats.authentication),
        (10, 10),
        "{stats:?}"
    );
}

#[test]
fn a_secured_profile_is_refused_without_its_key_or_with_bad_lengths_and_never_runs_plain() {
    let loaded = secured_profile("profile = \"24Bit-CMAC-8Bit-FV\"\nkey_id = 9\n").unwrap();
    let error = loaded
        .secured_wire(&key_file(), 1)
        .err()
        .unwrap()
        .to_string();
    assert!(
        error.contains("secoc.key_id: key 9 is not in the key file"),
        "{error}"
    );
    // The plain wire refuses a profile that declares SecOC.
    let error = bywire_vehicle::wire::ProfileWire::new(&loaded)
        .err()
        .unwrap()
        .to_string();
    assert!(
        error.contains("secoc: the profile secures its messages"),
        "{error}"
    );
    let error = secured_profile("profile = \"96Bit-HMAC\"\nkey_id = 3\n").unwrap_err();
    assert!(
        error.contains("secoc.profile: '96Bit-HMAC' is not a SecOC profile"),
        "{error}"
    );
    let error = secured_profile("fv_length = 8\nkey_id = 3\n").unwrap_err();
    assert!(
        error.contains("secoc: give profile, or fv_length"),
        "{error}"
    );
    let error = secured_profile("profile = \"24Bit-CMAC-8Bit-FV\"\nkey_id = 3\nsync_id = 0x100\n")
        .unwrap_err();
    assert!(
        error.contains("secoc.sync_id: 0x100 is not a free"),
        "{error}"
    );
    let error =
        secured_profile("fv_length = 64\nfv_tx_length = 8\nmac_tx_length = 480\nkey_id = 3\n")
            .unwrap_err();
    assert!(
        error.contains("secoc.messages[0]: AdsToVehicle_Control:"),
        "{error}"
    );
}

#[test]
fn forged_commands_alone_are_no_commands_the_watchdog_cascade_follows() {
    let mut bench = Bench::new(wire(1), wire(1));
    bench.quiet(200);
    let last = *bench.commands.last().unwrap();
    // The ADS falls silent; the attacker's commands keep coming, every cycle.
    let mut forged = forged_after(&last);
    for t in 200..400u64 {
        if t % 20 == 0 {
            bench.supervisor.on_frame(ms(t), Port::MAIN, &forged);
            forged = forged_after(&forged);
        }
        bench.supervisor.poll(ms(t), &mut |_, _| {});
    }
    let stats = bench.supervisor.stats();
    assert_eq!(stats.authentication, 10, "{stats:?}");
    assert_eq!(
        bench.supervisor.watchdog(),
        bywire_vehicle::supervisor::Watchdog::FullBraking
    );
}
