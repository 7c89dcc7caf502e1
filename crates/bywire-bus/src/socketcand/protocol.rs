//! The socketcand protocol's words: commands a client sends, the frames a server sends, in
//! both directions' text form.

use std::time::Duration;

use bywire_core::{ClassicFrame, Frame, Id, Timestamp};

/// The longest message accepted (between and including `<` and `>`); longer input is an error
/// and is discarded up to the next `>`.
pub const MAX_MESSAGE: usize = 256;

/// The longest interval `add`, `update`, `subscribe` and `filter` may give: a day.
pub const MAX_INTERVAL: Duration = Duration::from_secs(86_400);

/// A client command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// `auth TOKEN` (an extension of ours, for servers started with a token).
    Auth(String),
    /// `open NAME`.
    Open(String),
    /// `rawmode`.
    RawMode,
    /// `bcmmode`.
    BcmMode,
    /// `echo`.
    Echo,
    /// `send ID LEN DATA`.
    Send(Frame),
    /// `add SECS USECS ID LEN DATA`: send every interval (once when the interval is 0).
    Add(Duration, Frame),
    /// `update SECS USECS ID LEN DATA`: new data for a cyclic frame (and interval, if not 0).
    Update(Duration, Frame),
    /// `delete ID`.
    Delete(Id),
    /// `subscribe SECS USECS ID`: forward this identifier, throttled.
    Subscribe(Duration, Id),
    /// `filter SECS USECS ID LEN MASK`: forward this identifier when the bits under the mask
    /// change (the first frame always), throttled.
    Filter(Duration, Id, [u8; 8]),
    /// `unsubscribe ID`.
    Unsubscribe(Id),
}

fn id(text: &str) -> Result<Id, String> {
    let raw = u32::from_str_radix(text, 16).map_err(|_| format!("'{text}' is not a hex ID"))?;
    let result = if text.len() > 3 || raw > 0x7FF {
        Id::extended(raw)
    } else {
        Id::standard(raw)
    };
    result.map_err(|e| format!("ID {text}: {e}"))
}

fn frame(id_text: &str, len_text: &str, bytes: &[&str]) -> Result<Frame, String> {
    let id = id(id_text)?;
    let len =
        usize::from_str_radix(len_text, 16).map_err(|_| format!("'{len_text}' is not a length"))?;
    if len > 8 || bytes.len() != len {
        return Err(format!(
            "length {len} with {} data bytes (0 to 8, and equal)",
            bytes.len()
        ));
    }
    let mut data = [0u8; 8];
    for (slot, text) in data.iter_mut().zip(bytes) {
        if text.is_empty() || text.len() > 2 {
            return Err(format!("'{text}' is not a byte"));
        }
        *slot = u8::from_str_radix(text, 16).map_err(|_| format!("'{text}' is not a hex byte"))?;
    }
    ClassicFrame::new(id, data.get(..len).unwrap_or(&[]))
        .map(Frame::Classic)
        .map_err(|e| e.to_string())
}

/// `SECS USECS`: refused beyond [`MAX_INTERVAL`] or with a microsecond part of a second or
/// more, never clamped.
fn interval(secs: &str, usecs: &str) -> Result<Duration, String> {
    let s: u64 = secs
        .parse()
        .map_err(|_| format!("'{secs}' is not seconds"))?;
    let u: u64 = usecs
        .parse()
        .map_err(|_| format!("'{usecs}' is not microseconds"))?;
    if u > 999_999 {
        return Err(format!("{u} microseconds: at most 999999"));
    }
    let every = Duration::from_secs(s.min(u64::MAX / 2)) + Duration::from_micros(u);
    if every > MAX_INTERVAL {
        return Err(format!("interval {s} s: at most a day (86400 s)"));
    }
    Ok(every)
}

/// Parse the words between `<` and `>`.
pub fn parse_command(inner: &str) -> Result<Command, String> {
    let words: Vec<&str> = inner.split_whitespace().collect();
    match words.as_slice() {
        ["auth", token] => Ok(Command::Auth((*token).to_string())),
        ["open", name] => Ok(Command::Open((*name).to_string())),
        ["rawmode"] => Ok(Command::RawMode),
        ["bcmmode"] => Ok(Command::BcmMode),
        ["echo"] => Ok(Command::Echo),
        ["send", i, l, data @ ..] => frame(i, l, data).map(Command::Send),
        ["add", s, u, i, l, data @ ..] => Ok(Command::Add(interval(s, u)?, frame(i, l, data)?)),
        ["update", s, u, i, l, data @ ..] => {
            Ok(Command::Update(interval(s, u)?, frame(i, l, data)?))
        }
        ["delete", i] => id(i).map(Command::Delete),
        ["subscribe", s, u, i] => Ok(Command::Subscribe(interval(s, u)?, id(i)?)),
        ["filter", s, u, i, l, mask @ ..] => {
            let mask_frame = frame(i, l, mask)?;
            let mut bytes = [0u8; 8];
            for (b, m) in bytes.iter_mut().zip(mask_frame.data()) {
                *b = *m;
            }
            Ok(Command::Filter(interval(s, u)?, id(i)?, bytes))
        }
        ["unsubscribe", i] => id(i).map(Command::Unsubscribe),
        [] => Err("empty command".into()),
        [word, ..] => Err(format!("unknown or malformed command '{word}'")),
    }
}

/// A reply as the server sends it: `< TEXT >`. Angle brackets frame the protocol's messages,
/// so none may stand inside (an error quoting a client's text included), or the client would
/// read it as two.
pub fn format_reply(text: &str) -> String {
    format!("< {} >", text.replace(['<', '>'], ""))
}

fn id_text(id: Id) -> String {
    if id.is_extended() {
        format!("{:08X}", id.as_raw())
    } else {
        format!("{:03X}", id.as_raw())
    }
}

/// A frame as the server sends it: `< frame 123 1699999999.123456 DEADBEEF >`.
pub fn format_frame(frame: &Frame, timestamp: Timestamp) -> Option<String> {
    let id = frame.id()?;
    if frame.is_fd() || frame.is_remote() {
        return None; // socketcand's text has no way to say either
    }
    let nanos = timestamp.as_nanos();
    let data: String = frame.data().iter().map(|b| format!("{b:02X}")).collect();
    Some(format!(
        "< frame {} {}.{:06} {data} >",
        id_text(id),
        nanos / 1_000_000_000,
        nanos % 1_000_000_000 / 1000
    ))
}

/// A frame line from a server (`frame ID SECS.USECS DATA`, the words between `<` and `>`):
/// the frame and its timestamp.
pub fn parse_frame(inner: &str) -> Result<(Frame, Timestamp), String> {
    let words: Vec<&str> = inner.split_whitespace().collect();
    let (id_text, time, data) = match words.as_slice() {
        ["frame", i, t] => (*i, *t, ""),
        ["frame", i, t, d] => (*i, *t, *d),
        _ => return Err(format!("not a frame: '{inner}'")),
    };
    let raw = u32::from_str_radix(id_text, 16).map_err(|_| format!("bad ID '{id_text}'"))?;
    let id = if id_text.len() == 3 {
        Id::standard(raw)
    } else {
        Id::extended(raw)
    }
    .map_err(|e| e.to_string())?;
    let (secs, micros) = time.split_once('.').unwrap_or((time, "0"));
    let secs: u64 = secs.parse().map_err(|_| format!("bad time '{time}'"))?;
    let micros: u64 = micros.parse().map_err(|_| format!("bad time '{time}'"))?;
    let timestamp = Timestamp::from_nanos(
        secs.saturating_mul(1_000_000_000)
            .saturating_add(micros.min(999_999).saturating_mul(1000)),
    );
    if data.len() % 2 != 0 || data.len() > 16 {
        return Err(format!("bad data '{data}'"));
    }
    let mut bytes = [0u8; 8];
    for (i, slot) in bytes.iter_mut().enumerate().take(data.len() / 2) {
        let pair = data.get(2 * i..2 * i + 2).unwrap_or("");
        *slot = u8::from_str_radix(pair, 16).map_err(|_| format!("bad data '{data}'"))?;
    }
    let frame = ClassicFrame::new(id, bytes.get(..data.len() / 2).unwrap_or(&[]))
        .map_err(|e| e.to_string())?;
    Ok((Frame::Classic(frame), timestamp))
}

/// The `send` command for a frame (classic data frames only).
pub fn format_send(frame: &Frame) -> Option<String> {
    let id = frame.id()?;
    if frame.is_fd() || frame.is_remote() {
        return None;
    }
    let mut line = format!("< send {} {:X} ", id_text(id), frame.data().len());
    for byte in frame.data() {
        line.push_str(&format!("{byte:02X} "));
    }
    line.push('>');
    Some(line)
}

/// The words between the first `<` and the closing `>` of one message (`None`: no `<`).
pub fn inner_text(message: &str) -> Option<&str> {
    let start = message.find('<')?;
    let end = message.rfind('>').filter(|&end| end > start)?;
    message.get(start + 1..end)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_parse_and_refuse_clearly() {
        assert_eq!(
            parse_command(" open vcan0 "),
            Ok(Command::Open("vcan0".into()))
        );
        assert_eq!(
            parse_command(" auth s3cret "),
            Ok(Command::Auth("s3cret".into()))
        );
        assert_eq!(
            parse_command(" send 123 4 de ad be ef "),
            Ok(Command::Send("123#DEADBEEF".parse().unwrap()))
        );
        assert_eq!(
            parse_command(" send 1ABCDEF0 2 1 2 "),
            Ok(Command::Send("1ABCDEF0#0102".parse().unwrap()))
        );
        assert_eq!(
            parse_command(" add 0 100000 123 1 ff "),
            Ok(Command::Add(
                Duration::from_millis(100),
                "123#FF".parse().unwrap()
            ))
        );
        assert!(parse_command(" send 123 3 01 02 ")
            .unwrap_err()
            .contains("length 3 with 2"));
        assert!(parse_command(" send 12G 0 ")
            .unwrap_err()
            .contains("not a hex ID"));
        assert!(parse_command(" send 123 9 1 2 3 4 5 6 7 8 9 ").is_err());
        assert!(parse_command(" send 123 1 100 ")
            .unwrap_err()
            .contains("not a byte"));
        assert!(parse_command(" fly away ")
            .unwrap_err()
            .contains("unknown or malformed command 'fly'"));
        assert!(parse_command("").is_err());
    }

    #[test]
    fn intervals_out_of_range_are_refused_not_clamped() {
        assert_eq!(
            parse_command(" add 86400 0 123 0 "),
            Ok(Command::Add(MAX_INTERVAL, "123#".parse().unwrap()))
        );
        assert!(parse_command(" add 86401 0 123 0 ")
            .unwrap_err()
            .contains("at most a day"));
        assert!(parse_command(" add 0 1000000 123 0 ")
            .unwrap_err()
            .contains("at most 999999"));
        assert!(parse_command(" subscribe 99999999999999999999 0 123 ")
            .unwrap_err()
            .contains("not seconds"));
    }

    #[test]
    fn frames_print_and_parse_as_socketcand_does() {
        let t = Timestamp::from_nanos(1_699_999_999_123_456_789);
        let line = format_frame(&"123#DEADBEEF".parse().unwrap(), t).unwrap();
        assert_eq!(line, "< frame 123 1699999999.123456 DEADBEEF >");
        let (frame, at) = parse_frame(inner_text(&line).unwrap()).unwrap();
        assert_eq!(frame, "123#DEADBEEF".parse().unwrap());
        assert_eq!(at.as_nanos(), 1_699_999_999_123_456_000);
        assert_eq!(
            format_frame(&"00000123#".parse().unwrap(), t).unwrap(),
            "< frame 00000123 1699999999.123456  >"
        );
        assert_eq!(format_frame(&"123##1AA".parse().unwrap(), t), None);
        assert_eq!(
            format_send(&"123#0102".parse().unwrap()).unwrap(),
            "< send 123 2 01 02 >"
        );
        assert!(parse_frame("frame 12 0.0 GG").is_err());
    }

    #[test]
    fn replies_never_carry_an_angle_bracket() {
        assert_eq!(
            format_reply("error unknown command '<x>'"),
            "< error unknown command 'x' >"
        );
        assert_eq!(inner_text("junk < ok >"), Some(" ok "));
        assert_eq!(inner_text("ok >"), None);
    }
}
