//! Tokens of DBC text with their positions.

/// A token kind.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Tok {
    /// A name or keyword; `digit_start` when it begins with a digit (lenient names).
    Ident { text: String, digit_start: bool },
    /// A number, as written (`-12`, `0.25`, `.25`, `1e-3`).
    Number(String),
    /// A string, unescaped.
    Str(String),
    /// One of `: ; , | @ ( ) [ ] + -`.
    Punct(char),
    /// A character that fits nothing.
    Unexpected(char),
}

/// A token with where it is.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Token {
    pub tok: Tok,
    /// 1-based line.
    pub line: u32,
    /// 1-based column (characters).
    pub col: u32,
    /// Byte offsets in the text.
    pub start: usize,
    pub end: usize,
    /// First token on its line.
    pub line_start: bool,
}

pub(crate) fn tokenize(text: &str) -> Vec<Token> {
    let mut out = Vec::new();
    let mut chars = text.char_indices().peekable();
    let (mut line, mut col) = (1u32, 1u32);
    let mut line_start = true;
    while let Some(&(start, c)) = chars.peek() {
        if c == '\n' {
            chars.next();
            line += 1;
            col = 1;
            line_start = true;
            continue;
        }
        if c.is_whitespace() {
            chars.next();
            col += 1;
            continue;
        }
        // `//` comments to the end of the line: not in the DBC grammar, but common and accepted
        // by cantools.
        if c == '/' && text.get(start + 1..start + 2) == Some("/") {
            while chars.peek().is_some_and(|&(_, ch)| ch != '\n') {
                chars.next();
            }
            continue;
        }
        let (tok_line, tok_col) = (line, col);
        let mut end = start + c.len_utf8();
        let advance = |chars: &mut std::iter::Peekable<std::str::CharIndices<'_>>,
                       col: &mut u32| {
            if let Some((i, ch)) = chars.next() {
                *col += 1;
                Some((i, ch))
            } else {
                None
            }
        };
        let tok = if c == '"' {
            advance(&mut chars, &mut col);
            let mut s = String::new();
            let mut escaped = false;
            while let Some((i, ch)) = advance(&mut chars, &mut col) {
                end = i + ch.len_utf8();
                if ch == '\n' {
                    line += 1;
                    col = 1;
                }
                if escaped {
                    s.push(ch);
                    escaped = false;
                } else if ch == '\\' {
                    escaped = true;
                } else if ch == '"' {
                    break;
                } else {
                    s.push(ch);
                }
            }
            Tok::Str(s)
        } else if is_number_start(c, text.get(start + 1..)) {
            let mut s = String::new();
            let mut word = false;
            while let Some(&(i, ch)) = chars.peek() {
                let prev = s.chars().last();
                let exponent_sign =
                    (ch == '-' || ch == '+') && matches!(prev, Some('e' | 'E')) && !word;
                let ok = ch.is_ascii_digit()
                    || ch == '.'
                    || ((ch == '-' || ch == '+') && s.is_empty())
                    || exponent_sign
                    || ch.is_ascii_alphabetic()
                    || ch == '_';
                if !ok {
                    break;
                }
                if (ch.is_ascii_alphabetic() && ch != 'e' && ch != 'E') || ch == '_' {
                    word = true;
                }
                s.push(ch);
                end = i + ch.len_utf8();
                advance(&mut chars, &mut col);
            }
            if word || (s.contains(['e', 'E']) && s.parse::<f64>().is_err()) {
                Tok::Ident {
                    text: s,
                    digit_start: true,
                }
            } else {
                Tok::Number(s)
            }
        } else if c.is_alphabetic() || c == '_' {
            let mut s = String::new();
            while let Some(&(i, ch)) = chars.peek() {
                if !(ch.is_alphanumeric() || ch == '_') {
                    break;
                }
                s.push(ch);
                end = i + ch.len_utf8();
                advance(&mut chars, &mut col);
            }
            Tok::Ident {
                text: s,
                digit_start: false,
            }
        } else {
            advance(&mut chars, &mut col);
            if ":;,|@()[]+-".contains(c) {
                Tok::Punct(c)
            } else {
                Tok::Unexpected(c)
            }
        };
        out.push(Token {
            tok,
            line: tok_line,
            col: tok_col,
            start,
            end,
            line_start,
        });
        line_start = false;
    }
    out
}

/// A number starts with a digit, a `.` before a digit, or a sign before either.
fn is_number_start(c: char, rest: Option<&str>) -> bool {
    let mut next = rest.unwrap_or("").chars();
    let n1 = next.next();
    let n2 = next.next();
    let digit = |x: Option<char>| x.is_some_and(|x| x.is_ascii_digit());
    c.is_ascii_digit()
        || (c == '.' && digit(n1))
        || ((c == '-' || c == '+') && (digit(n1) || (n1 == Some('.') && digit(n2))))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kinds(text: &str) -> Vec<Tok> {
        tokenize(text).into_iter().map(|t| t.tok).collect()
    }

    #[test]
    fn numbers_signs_and_names() {
        assert_eq!(
            kinds("(.25,-500) @1- 1e-3 2ABC"),
            vec![
                Tok::Punct('('),
                Tok::Number(".25".into()),
                Tok::Punct(','),
                Tok::Number("-500".into()),
                Tok::Punct(')'),
                Tok::Punct('@'),
                Tok::Number("1".into()),
                Tok::Punct('-'),
                Tok::Number("1e-3".into()),
                Tok::Ident {
                    text: "2ABC".into(),
                    digit_start: true
                },
            ]
        );
        let t = tokenize("A\n  \"x\\\"y\nz\" B");
        assert_eq!(t[1].tok, Tok::Str("x\"y\nz".into()));
        assert_eq!((t[2].line, t[2].col, t[2].line_start), (3, 4, false));
    }
}
