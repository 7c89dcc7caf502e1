//! Text as legacy tools write it: DBC and EDS files from Windows tools are often Windows-1252
//! (Latin-1 with typographic characters in 0x80..0x9F), not UTF-8.

/// The character a Windows-1252 byte stands for (the five undefined bytes as their C1 control
/// characters, as Python's `cp1252` with `errors="ignore"` would not — nothing is dropped).
pub fn cp1252_char(byte: u8) -> char {
    const HIGH: [char; 32] = [
        '€', '\u{81}', '‚', 'ƒ', '„', '…', '†', '‡', 'ˆ', '‰', 'Š', '‹', 'Œ', '\u{8D}', 'Ž',
        '\u{8F}', '\u{90}', '‘', '’', '“', '”', '•', '–', '—', '˜', '™', 'š', '›', 'œ', '\u{9D}',
        'ž', 'Ÿ',
    ];
    match byte {
        0x80..=0x9F => HIGH
            .get(usize::from(byte - 0x80))
            .copied()
            .unwrap_or('\u{FFFD}'),
        _ => char::from(byte),
    }
}

/// The characters of Windows-1252 `bytes`.
pub fn cp1252_chars(bytes: &[u8]) -> impl Iterator<Item = char> + '_ {
    bytes.iter().map(|&b| cp1252_char(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latin_1_and_the_windows_extras() {
        assert_eq!(cp1252_char(b'A'), 'A');
        assert_eq!(cp1252_char(0xE9), 'é');
        assert_eq!(cp1252_char(0xB0), '°');
        assert_eq!(cp1252_char(0x80), '€');
        assert_eq!(cp1252_char(0x81), '\u{81}');
        assert!(cp1252_chars(b"\xb5s").eq(['µ', 's']));
    }
}
