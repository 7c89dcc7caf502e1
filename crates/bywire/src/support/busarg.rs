//! Bus arguments as the can-utils commands take them: a bus spec (`socketcan:can0`,
//! `virtual:test`, `sim:a@500000`, or a plain interface name such as `can0` for SocketCAN),
//! optionally followed by candump's filters (`can0,123:7FF,1F0~7F0,#FFFFFFFF,j`), and
//! optionally preceded by the label it is shown and logged under (`front=socketcan:can0`).

use std::io::Write;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{anyhow, Context, Result};
use bywire_bus::{Bus, Filtering, Received};
use bywire_core::filter::FilterItem;

/// A bus argument.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BusArg {
    /// The full spec (`socketcan:can0` for a plain `can0`).
    pub spec: String,
    /// The name shown in output and written to logs: the label given (`front=can0`), else the
    /// interface for SocketCAN, what follows the last `/` where there is one, up to an `@`
    /// (`socketcand:HOST:PORT/bus1` is `bus1`, `slcan:/dev/ttyACM0@500000` is `ttyACM0`), the
    /// spec as given otherwise.
    pub name: String,
    /// The filters, when any were given.
    pub filtering: Option<Filtering>,
}

/// The full spec for what a user typed: a plain interface name means SocketCAN.
pub fn full_spec(text: &str) -> String {
    if text.contains(':') {
        text.to_string()
    } else {
        format!("socketcan:{text}")
    }
}

/// Parse `[LABEL=]SPEC[,FILTER]*`.
pub fn parse(text: &str) -> Result<BusArg> {
    let mut parts = text.split(',');
    let first = parts.next().unwrap_or_default();
    let (label, given) = match first.split_once('=') {
        Some((label, given)) => (Some(label), given),
        None => (None, first),
    };
    if given.is_empty() {
        return Err(anyhow!("bus '{text}': no bus before the filters"));
    }
    if let Some(label) = label.filter(|l| !is_label(l)) {
        return Err(anyhow!(
            "bus '{text}': label '{label}' is not a name (letters, digits, '_', '-', '.'; at \
             most 32)"
        ));
    }
    let spec = full_spec(given);
    let name = match (label, spec.strip_prefix("socketcan:")) {
        (Some(label), _) => label,
        (None, Some(interface)) => interface,
        (None, None) => given
            .rsplit_once('/')
            .map(|(_, last)| last.split('@').next().unwrap_or(last))
            .filter(|last| !last.is_empty())
            .unwrap_or(given),
    }
    .to_string();
    let mut filtering: Option<Filtering> = None;
    let mut data_filters = Vec::new();
    for item in parts {
        let f = filtering.get_or_insert_with(Filtering::default);
        match item
            .parse::<FilterItem>()
            .with_context(|| format!("bus '{text}': filter '{item}'"))?
        {
            FilterItem::Filter(filter) => data_filters.push(filter),
            FilterItem::ErrorMask(mask) => f.error_mask = mask,
            FilterItem::Join => f.join = true,
        }
    }
    // As candump: without data filters every data frame passes (the socket's default).
    if let Some(f) = filtering.as_mut() {
        if !data_filters.is_empty() {
            f.filters = data_filters;
        }
    }
    Ok(BusArg {
        spec,
        name,
        filtering,
    })
}

impl BusArg {
    /// Open the bus and apply the filters.
    pub fn open(&self) -> Result<Box<dyn Bus>> {
        self.open_filtered(None)
    }

    /// Open the bus and apply the filters, or `otherwise` when none were given.
    pub fn open_filtered(&self, otherwise: Option<Filtering>) -> Result<Box<dyn Bus>> {
        let bus = bywire_bus::open(&self.spec)?;
        self.filter(bus, self.filtering.clone().or(otherwise))
    }

    /// Open the bus for listening only (see [`bywire_bus::open_listening`]) and apply the
    /// filters, or `otherwise` when none were given.
    pub fn open_listening(
        &self,
        otherwise: Option<Filtering>,
    ) -> Result<(Box<dyn Bus>, bywire_bus::Listening)> {
        let (bus, listening) = bywire_bus::open_listening(&self.spec)?;
        let bus = self.filter(bus, self.filtering.clone().or(otherwise))?;
        Ok((bus, listening))
    }

    fn filter(&self, mut bus: Box<dyn Bus>, filtering: Option<Filtering>) -> Result<Box<dyn Bus>> {
        if let Some(filtering) = filtering {
            bus.set_filtering(filtering)
                .with_context(|| format!("{}: cannot set the filters", self.spec))?;
        }
        Ok(bus)
    }
}

/// One received frame (with the index of its bus), or the error that ended a bus's reader.
pub type Event = (usize, Result<Received, String>);

/// One reader thread per bus feeding one channel, so several buses print in arrival order.
/// Dropping it stops and joins the threads.
pub struct Readers {
    /// Frames from every bus.
    pub events: Receiver<Event>,
    /// Each bus's receive drops so far (its endpoint's count: the kernel's for SocketCAN),
    /// brought up to date as its reader goes.
    pub dropped: Vec<Arc<AtomicU64>>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl Readers {
    /// Start reading `buses` (already opened, in the order their indexes refer to); a bus's
    /// reader ends at its first error.
    pub fn start(buses: Vec<Box<dyn Bus>>) -> Readers {
        Readers::start_with(buses, false)
    }

    /// The same; with `keep_going`, a bus's reader goes on after an error (reported as an
    /// event, then a pause of 100 ms): an interface that went down may come back (candump -D).
    pub fn start_with(buses: Vec<Box<dyn Bus>>, keep_going: bool) -> Readers {
        let stop = Arc::new(AtomicBool::new(false));
        // Bounded: a stalled printer holds the readers back instead of growing without end
        // (the buses' own receive queues count what is lost then).
        let (tx, events) = mpsc::sync_channel::<Event>(4096);
        let dropped: Vec<Arc<AtomicU64>> = buses.iter().map(|_| Arc::default()).collect();
        let threads = buses
            .into_iter()
            .zip(&dropped)
            .enumerate()
            .map(|(index, (mut bus, dropped))| {
                let (tx, stop, dropped) = (tx.clone(), Arc::clone(&stop), Arc::clone(dropped));
                std::thread::spawn(move || {
                    let mut since_count = 0u32;
                    while !stop.load(Ordering::Relaxed) {
                        let event = match bus.recv(Some(Duration::from_millis(100))) {
                            Ok(None) => {
                                dropped.store(bus.stats().rx_dropped, Ordering::Relaxed);
                                continue;
                            }
                            Ok(Some(received)) => Ok(received),
                            Err(e) => Err(e.to_string()),
                        };
                        since_count += 1;
                        if since_count >= 256 {
                            since_count = 0;
                            dropped.store(bus.stats().rx_dropped, Ordering::Relaxed);
                        }
                        let failed = event.is_err();
                        if tx.send((index, event)).is_err() || (failed && !keep_going) {
                            break;
                        }
                        if failed {
                            std::thread::sleep(Duration::from_millis(100));
                        }
                    }
                })
            })
            .collect();
        Readers {
            events,
            dropped,
            stop,
            threads,
        }
    }
}

impl Drop for Readers {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Unblock readers waiting to hand over a frame.
        while self.events.try_recv().is_ok() {}
        for thread in self.threads.drain(..) {
            while !thread.is_finished() {
                while self.events.try_recv().is_ok() {}
                std::thread::sleep(Duration::from_millis(5));
            }
            let _ = thread.join();
        }
    }
}

/// A label a bus can be given: what logs and columns can carry as an interface name.
fn is_label(label: &str) -> bool {
    (1..=32).contains(&label.len())
        && label
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_-.".contains(c))
}

/// Open every bus argument (all before any is read, so a bad one fails before output starts).
pub fn open_all(buses: &[BusArg]) -> Result<Vec<Box<dyn Bus>>> {
    buses
        .iter()
        .map(|b| b.open().with_context(|| format!("bus '{}'", b.spec)))
        .collect()
}

/// Open a bus named by a plain spec (no filters).
pub fn open(text: &str) -> Result<Box<dyn Bus>> {
    Ok(bywire_bus::open(&full_spec(text))?)
}

/// Open a bus a one-shot sender (send, gen) sends on, saying on standard error when it lives
/// inside this process, where nothing outside hears what is sent.
pub fn open_to_send(text: &str, command: &str) -> Result<Box<dyn Bus>> {
    let spec = full_spec(text);
    if bywire_bus::is_in_process(&spec) {
        let _ = writeln!(
            std::io::stderr(),
            "bywire {command}: {spec} is a bus inside this process: no other process hears \
             it (for others: socketcan:IFACE, udp:GROUP:PORT, or socketcand:HOST:PORT/BUS of \
             bywire sim --serve or bywire serve)"
        );
    }
    Ok(bywire_bus::open(&spec)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_names_are_socketcan_and_filters_follow_candump() {
        let a = parse("can0").unwrap();
        assert_eq!(
            (a.spec.as_str(), a.name.as_str()),
            ("socketcan:can0", "can0")
        );
        assert!(a.filtering.is_none());
        let a = parse("virtual:x,123:7FF,#FFFFFFFF,j").unwrap();
        assert_eq!(a.name, "virtual:x");
        let f = a.filtering.unwrap();
        assert_eq!(f.filters.len(), 1);
        assert!(f.join && f.error_mask.0 == 0xFFFF_FFFF);
        let f = parse("can0,#4").unwrap().filtering.unwrap();
        assert_eq!(f.filters, Filtering::default().filters);
        let e = parse("can0,12G:7FF").unwrap_err();
        assert!(format!("{e:#}").contains("filter '12G:7FF'"), "{e:#}");
        assert!(parse(",123:7FF").is_err());
    }

    #[test]
    fn remote_buses_are_named_by_what_follows_their_last_slash() {
        let name = |text| parse(text).unwrap().name;
        assert_eq!(name("socketcand:127.0.0.1:29536/bus1,123:7FF"), "bus1");
        assert_eq!(name("slcan:/dev/ttyACM0@500000"), "ttyACM0");
        assert_eq!(name("udp:239.0.0.1:43113"), "udp:239.0.0.1:43113");
        assert_eq!(name("socketcand:host:29536/"), "socketcand:host:29536/");
    }

    #[test]
    fn a_label_names_the_bus_it_precedes() {
        let a = parse("front=socketcand:127.0.0.1:29536/bus1,123:7FF").unwrap();
        assert_eq!(
            (a.spec.as_str(), a.name.as_str()),
            ("socketcand:127.0.0.1:29536/bus1", "front")
        );
        assert_eq!(a.filtering.unwrap().filters.len(), 1);
        assert_eq!(parse("rear=can1").unwrap().spec, "socketcan:can1");
        for bad in ["=can0", "a b=can0", "front=", "front=,123:7FF"] {
            assert!(parse(bad).is_err(), "{bad}");
        }
    }
}
