//! socketcand's discovery beacon: a UDP datagram every three seconds saying where a server
//! listens and which buses it serves (python-can's `detect_beacon` reads it).

use std::net::{SocketAddr, UdpSocket};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The beacon's XML: where the server listens, which buses it serves, and what it is
/// (`description`).
pub fn beacon_xml(listen: SocketAddr, buses: &[String], description: &str) -> String {
    let escape = |text: &str| {
        text.replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('>', "&gt;")
            .replace('"', "&quot;")
    };
    let mut xml = format!(
        "<CANBeacon name=\"bywire\" type=\"SocketCAN\" description=\"{}\"><URL>can://{listen}</URL>",
        escape(description)
    );
    for bus in buses {
        xml.push_str(&format!("<Bus name=\"{}\"/>", escape(bus)));
    }
    xml.push_str("</CANBeacon>");
    xml
}

/// Send `xml` to `to` every three seconds (as socketcand does) until `stopping` says so.
pub(super) fn spawn(
    xml: String,
    to: SocketAddr,
    stopping: impl Fn() -> bool + Send + 'static,
) -> std::io::Result<JoinHandle<()>> {
    let socket = UdpSocket::bind("0.0.0.0:0")?;
    socket.set_broadcast(true)?;
    std::thread::Builder::new()
        .name("socketcand-beacon".into())
        .spawn(move || {
            let mut next = Instant::now();
            while !stopping() {
                if Instant::now() >= next {
                    let _ = socket.send_to(xml.as_bytes(), to);
                    next += Duration::from_secs(3);
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_beacon_names_the_buses_escaped() {
        let xml = beacon_xml("127.0.0.1:29536".parse().unwrap(), &["a<b".into()], "x&y");
        assert_eq!(
            xml,
            "<CANBeacon name=\"bywire\" type=\"SocketCAN\" description=\"x&amp;y\"><URL>can://127.0.0.1:29536</URL><Bus name=\"a&lt;b\"/></CANBeacon>"
        );
    }
}
