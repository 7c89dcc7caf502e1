//! Signal conditions such as `VehicleToAds_State.WatchdogLevel >= 3` or
//! `VehicleToAds_State.ControlMode == Manual`: parsed from text, checked against a database
//! once, then evaluated on frames (a logger's trigger, a filter).
//!
//! The value is a number compared with the signal's physical value, or one of the signal's
//! value descriptions compared with its raw value (a name needs no knowledge of the scale).

use std::fmt;

use bywire_core::Frame;

use crate::codec::Decoded;
use crate::decoder::Decoder;

/// How a signal is compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Comparison {
    /// `==`
    Equal,
    /// `!=`
    NotEqual,
    /// `<`
    Less,
    /// `<=`
    LessOrEqual,
    /// `>`
    Greater,
    /// `>=`
    GreaterOrEqual,
}

impl Comparison {
    /// Longest first, so `>=` is not read as `>`.
    const TEXTS: [(&'static str, Comparison); 6] = [
        ("==", Comparison::Equal),
        ("!=", Comparison::NotEqual),
        ("<=", Comparison::LessOrEqual),
        (">=", Comparison::GreaterOrEqual),
        ("<", Comparison::Less),
        (">", Comparison::Greater),
    ];

    fn text(self) -> &'static str {
        Self::TEXTS
            .iter()
            .find(|(_, c)| *c == self)
            .map_or("?", |(t, _)| t)
    }

    fn holds<T: PartialOrd>(self, left: T, right: T) -> bool {
        match self {
            Comparison::Equal => left == right,
            Comparison::NotEqual => left != right,
            Comparison::Less => left < right,
            Comparison::LessOrEqual => left <= right,
            Comparison::Greater => left > right,
            Comparison::GreaterOrEqual => left >= right,
        }
    }
}

/// What a signal is compared with.
#[derive(Debug, Clone, PartialEq)]
pub enum Operand {
    /// A physical value.
    Number(f64),
    /// A value description's name (compared with the raw value it describes).
    Name(String),
}

/// `MESSAGE.SIGNAL OP VALUE`, as written.
#[derive(Debug, Clone, PartialEq)]
pub struct Condition {
    /// The message's name.
    pub message: String,
    /// The signal's name.
    pub signal: String,
    /// The comparison.
    pub comparison: Comparison,
    /// The value.
    pub operand: Operand,
}

impl fmt::Display for Condition {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}.{} {} ",
            self.message,
            self.signal,
            self.comparison.text()
        )?;
        match &self.operand {
            Operand::Number(n) => write!(f, "{n}"),
            Operand::Name(name) => f.write_str(name),
        }
    }
}

impl std::str::FromStr for Condition {
    type Err = String;

    /// `MESSAGE.SIGNAL OP VALUE` (spaces around the operator optional).
    fn from_str(text: &str) -> Result<Condition, String> {
        let (at, (op_text, comparison)) = Comparison::TEXTS
            .iter()
            .filter_map(|entry| text.find(entry.0).map(|at| (at, *entry)))
            .min_by_key(|(at, (op, _))| (*at, usize::MAX - op.len()))
            .ok_or_else(|| {
                format!("'{text}': no comparison (one of == != < <= > >=) in the condition")
            })?;
        let left = text.get(..at).unwrap_or_default().trim();
        let right = text.get(at + op_text.len()..).unwrap_or_default().trim();
        let (message, signal) = left
            .split_once('.')
            .filter(|(m, s)| !m.is_empty() && !s.is_empty())
            .ok_or_else(|| format!("'{text}': '{left}' is not MESSAGE.SIGNAL"))?;
        if right.is_empty() {
            return Err(format!("'{text}': no value after '{op_text}'"));
        }
        let operand = match right.parse::<f64>() {
            Ok(n) if n.is_finite() => Operand::Number(n),
            Ok(_) => return Err(format!("'{text}': the value must be a finite number")),
            Err(_) if right.chars().all(|c| c.is_alphanumeric() || c == '_') => {
                Operand::Name(right.to_string())
            }
            Err(_) => {
                return Err(format!(
                    "'{text}': '{right}' is neither a number nor a value description's name"
                ))
            }
        };
        Ok(Condition {
            message: message.to_string(),
            signal: signal.to_string(),
            comparison,
            operand,
        })
    }
}

/// A condition checked against a database: where its signal is and what it is compared with.
#[derive(Debug, Clone, PartialEq)]
pub struct Compiled {
    condition: Condition,
    id: u32,
    extended: bool,
    index: usize,
    against: Against,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Against {
    Physical(f64),
    Raw(u64),
}

impl Condition {
    /// Find the signal in `decoder`'s database (and a named value among its descriptions); an
    /// error names what is missing.
    pub fn compile(&self, decoder: &Decoder) -> Result<Compiled, String> {
        let message = decoder
            .database()
            .message_by_name(&self.message)
            .ok_or_else(|| format!("{self}: the DBC has no message '{}'", self.message))?;
        let (index, signal) = message
            .signals
            .iter()
            .enumerate()
            .find(|(_, s)| s.name == self.signal)
            .ok_or_else(|| format!("{self}: {} has no signal '{}'", self.message, self.signal))?;
        let against = match &self.operand {
            Operand::Number(n) => Against::Physical(*n),
            Operand::Name(name) => {
                let raw = signal
                    .value_descriptions
                    .iter()
                    .find(|(_, text)| text == name)
                    .map(|(raw, _)| *raw)
                    .ok_or_else(|| {
                        let known: Vec<&str> = signal
                            .value_descriptions
                            .iter()
                            .map(|(_, t)| t.as_str())
                            .collect();
                        format!(
                            "{self}: {}.{} has no value named '{name}' (it has: {})",
                            self.message,
                            self.signal,
                            if known.is_empty() {
                                "none".to_string()
                            } else {
                                known.join(", ")
                            }
                        )
                    })?;
                // The raw bits as the decoder gives them: two's complement for a negative.
                let bits = raw & i128::from(width_mask(signal.length));
                Against::Raw(u64::try_from(bits).unwrap_or(u64::MAX))
            }
        };
        Ok(Compiled {
            condition: self.clone(),
            id: message.id,
            extended: message.extended,
            index,
            against,
        })
    }
}

fn width_mask(bits: u32) -> u64 {
    if bits >= 64 {
        u64::MAX
    } else {
        (1u64 << bits) - 1
    }
}

impl Compiled {
    /// The condition as written.
    pub fn condition(&self) -> &Condition {
        &self.condition
    }

    /// Whether `frame` is the condition's message (by identifier).
    pub fn is_its_message(&self, frame: &Frame) -> bool {
        frame
            .id()
            .is_some_and(|id| id.as_raw() == self.id && id.is_extended() == self.extended)
    }

    /// Whether the condition holds on `frame`: `None` when the frame is another message or
    /// does not carry the signal (too short, another multiplexer value). `values` is scratch
    /// space the caller keeps, so evaluating allocates nothing once it has grown.
    pub fn holds(
        &self,
        decoder: &Decoder,
        frame: &Frame,
        values: &mut Vec<Option<Decoded>>,
    ) -> Option<bool> {
        if !self.is_its_message(frame) {
            return None;
        }
        let (_, _, result) = decoder.decode_into(frame, values)?;
        result.ok()?;
        let value = (*values.get(self.index)?)?;
        Some(match self.against {
            Against::Physical(n) => self.condition.comparison.holds(value.physical.as_f64(), n),
            Against::Raw(raw) => self.condition.comparison.holds(value.raw, raw),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bywire_core::frame::ClassicFrame;
    use bywire_core::Id;

    const DBC: &str = "BU_: ECU ADS\nBO_ 257 State: 8 ECU\n SG_ Level : 0|8@1+ (1,0) [0|7] \"\" ADS\n SG_ Mode : 8|8@1+ (1,0) [0|3] \"\" ADS\n SG_ Speed : 16|16@1- (0.01,0) [-50|50] \"m/s\" ADS\nVAL_ 257 Mode 0 \"Manual\" 1 \"Autonomous\" ;\n";

    fn decoder() -> Decoder {
        let (db, _) = crate::parse_str(DBC, crate::Mode::Lenient).unwrap();
        Decoder::new(db)
    }

    fn frame(level: u8, mode: u8, speed: i16) -> Frame {
        let s = speed.to_le_bytes();
        Frame::Classic(
            ClassicFrame::new(
                Id::standard(257).unwrap(),
                &[level, mode, s[0], s[1], 0, 0, 0, 0],
            )
            .unwrap(),
        )
    }

    fn holds(text: &str, frame: &Frame) -> Option<bool> {
        let decoder = decoder();
        let compiled = text
            .parse::<Condition>()
            .unwrap()
            .compile(&decoder)
            .unwrap();
        compiled.holds(&decoder, frame, &mut Vec::new())
    }

    #[test]
    fn conditions_compare_physical_values_and_named_raw_values() {
        let f = frame(3, 1, -250);
        assert_eq!(holds("State.Level >= 3", &f), Some(true));
        assert_eq!(holds("State.Level>3", &f), Some(false));
        assert_eq!(holds("State.Level != 3", &f), Some(false));
        assert_eq!(holds("State.Level < 4", &f), Some(true));
        assert_eq!(holds("State.Speed <= -2.5", &f), Some(true));
        assert_eq!(holds("State.Speed < -2.5", &f), Some(false));
        assert_eq!(holds("State.Mode == Autonomous", &f), Some(true));
        assert_eq!(holds("State.Mode == Manual", &f), Some(false));
        let other = Frame::Classic(ClassicFrame::new(Id::standard(258).unwrap(), &[9; 8]).unwrap());
        assert_eq!(holds("State.Level >= 3", &other), None);
        // Too short to carry the signal.
        let short = Frame::Classic(ClassicFrame::new(Id::standard(257).unwrap(), &[3]).unwrap());
        assert_eq!(holds("State.Speed > 0", &short), None);
    }

    #[test]
    fn bad_conditions_say_what_is_wrong() {
        let decoder = decoder();
        let error = |text: &str| match text.parse::<Condition>() {
            Err(e) => e,
            Ok(c) => c.compile(&decoder).unwrap_err(),
        };
        assert!(error("State.Level").contains("no comparison"));
        assert!(error("Level >= 3").contains("not MESSAGE.SIGNAL"));
        assert!(error("State.Level >=").contains("no value"));
        assert!(error("State.Level >= inf").contains("finite"));
        assert!(error("State.Level >= 3 4").contains("neither a number"));
        assert!(error("Nope.Level >= 3").contains("no message 'Nope'"));
        assert!(error("State.Nope >= 3").contains("no signal 'Nope'"));
        let named = error("State.Mode == Parked");
        assert!(named.contains("no value named 'Parked'") && named.contains("Manual, Autonomous"));
        assert_eq!(
            "State.Level>=3".parse::<Condition>().unwrap().to_string(),
            "State.Level >= 3"
        );
    }
}
