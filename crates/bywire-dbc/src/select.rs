//! Signals chosen by name, as `cantools plot` chooses them: `SIGNAL` or `MESSAGE.SIGNAL`, each
//! part exact or a shell-style pattern (`*` any run of characters, `?` any one), so
//! `'*Velocity*'` or `'VehicleToAds_*.Wheel*'` pick every signal they match.

use crate::Database;

/// Whether `text` matches the shell-style `pattern` (`*` and `?`; every other character
/// stands for itself). Iterative, with one backtrack point: at most
/// `pattern.len() × text.len()` steps.
pub fn glob_matches(pattern: &str, text: &str) -> bool {
    let (p, t): (Vec<char>, Vec<char>) = (pattern.chars().collect(), text.chars().collect());
    let (mut pi, mut ti) = (0, 0);
    let mut star: Option<(usize, usize)> = None;
    while ti < t.len() {
        match p.get(pi) {
            Some('*') => {
                star = Some((pi, ti));
                pi += 1;
            }
            Some(c) if *c == '?' || Some(c) == t.get(ti) => {
                pi += 1;
                ti += 1;
            }
            _ => match star {
                // Let the last `*` take one more character and try again.
                Some((sp, st)) => {
                    pi = sp + 1;
                    ti = st + 1;
                    star = Some((sp, st + 1));
                }
                None => return false,
            },
        }
    }
    p.get(pi..)
        .is_some_and(|rest| rest.iter().all(|c| *c == '*'))
}

/// The signals `spec` names, as (message index, signal index) in file order: `SIGNAL` or
/// `MESSAGE.SIGNAL`, by name or display name, each part exact or a pattern.
pub fn signals_matching(db: &Database, spec: &str) -> Vec<(usize, usize)> {
    let (message, signal) = match spec.split_once('.') {
        Some((m, s)) => (Some(m), s),
        None => (None, spec),
    };
    let named = |pattern: &str, name: &str, display: &str| {
        glob_matches(pattern, name) || glob_matches(pattern, display)
    };
    let mut found = Vec::new();
    for (mi, m) in db.messages.iter().enumerate() {
        if message.is_some_and(|p| !named(p, &m.name, m.display_name())) {
            continue;
        }
        for (si, s) in m.signals.iter().enumerate() {
            if named(signal, &s.name, s.display_name()) {
                found.push((mi, si));
            }
        }
    }
    found
}

/// Whether `spec` is a pattern (it may name many signals) rather than a name.
pub fn is_pattern(spec: &str) -> bool {
    spec.contains(['*', '?'])
}

#[cfg(test)]
mod tests {
    use super::glob_matches;

    #[test]
    fn patterns_match_as_a_shell_matches_them() {
        for (pattern, text, matches) in [
            ("*Velocity*", "VelocityActual", true),
            ("*Velocity*", "WheelVelocityFL", true),
            ("*Velocity", "VelocityActual", false),
            ("Wheel?peed", "WheelSpeed", true),
            ("Wheel?peed", "Wheelspeed", true),
            ("Wheel?peed", "WheelSpeeds", false),
            ("*", "", true),
            ("", "", true),
            ("", "x", false),
            ("a*b*c", "axxbyyc", true),
            ("a*b*c", "axxbyy", false),
            ("**a", "ba", true),
            ("Exact", "Exact", true),
        ] {
            assert_eq!(glob_matches(pattern, text), matches, "{pattern} ~ {text}");
        }
    }
}
