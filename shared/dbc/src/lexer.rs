//! Splits DBC text into tokens that remember where they stood, so every parse error can
//! name its line and column.

use crate::ParseError;

/// What a token is.
#[derive(Clone, Debug, PartialEq)]
pub enum TokenKind {
    /// Keyword or name: `BO_`, `EngineMsg`, `Vector__XXX`.
    Ident(String),
    /// A number as written (integer or decimal, optionally signed, optionally with exponent).
    Number(String),
    /// A double-quoted string, unescaped.
    Str(String),
    /// One punctuation character: `: | @ + - ( ) [ ] , ;`.
    Punct(char),
}

/// A token and where it starts (1-based line and column).
#[derive(Clone, Debug, PartialEq)]
pub struct Token {
    /// The token.
    pub kind: TokenKind,
    /// Line of its first character.
    pub line: usize,
    /// Column of its first character.
    pub column: usize,
}

impl TokenKind {
    /// How the token reads in an error message.
    pub fn describe(&self) -> String {
        match self {
            TokenKind::Ident(s) => format!("'{s}'"),
            TokenKind::Number(s) => format!("number {s}"),
            TokenKind::Str(s) => format!("string \"{s}\""),
            TokenKind::Punct(c) => format!("'{c}'"),
        }
    }
}

/// Tokenises a whole DBC file. `//` starts a comment that runs to the end of the line.
pub fn tokenize(text: &str) -> Result<Vec<Token>, ParseError> {
    let chars: Vec<char> = text.chars().collect();
    let mut tokens = Vec::new();
    let (mut i, mut line, mut column) = (0usize, 1usize, 1usize);

    let advance = |i: &mut usize, line: &mut usize, column: &mut usize, c: char| {
        *i += 1;
        if c == '\n' {
            *line += 1;
            *column = 1;
        } else {
            *column += 1;
        }
    };

    while i < chars.len() {
        let c = chars[i];
        let (start_line, start_column) = (line, column);
        if c.is_whitespace() || c == '\u{feff}' {
            advance(&mut i, &mut line, &mut column, c);
            continue;
        }
        if c == '/' && chars.get(i + 1) == Some(&'/') {
            while i < chars.len() && chars[i] != '\n' {
                let c = chars[i];
                advance(&mut i, &mut line, &mut column, c);
            }
            continue;
        }
        let kind = if c.is_ascii_alphabetic() || c == '_' {
            let mut s = String::new();
            while i < chars.len() && (chars[i].is_ascii_alphanumeric() || chars[i] == '_') {
                s.push(chars[i]);
                let c = chars[i];
                advance(&mut i, &mut line, &mut column, c);
            }
            TokenKind::Ident(s)
        } else if c.is_ascii_digit()
            || ((c == '-' || c == '+' || c == '.')
                && chars
                    .get(i + 1)
                    .is_some_and(|n| n.is_ascii_digit() || *n == '.'))
        {
            let mut s = String::new();
            s.push(c);
            advance(&mut i, &mut line, &mut column, c);
            while i < chars.len() {
                let d = chars[i];
                let exponent_sign =
                    (d == '-' || d == '+') && matches!(s.chars().last(), Some('e' | 'E'));
                if d.is_ascii_digit() || d == '.' || d == 'e' || d == 'E' || exponent_sign {
                    s.push(d);
                    advance(&mut i, &mut line, &mut column, d);
                } else {
                    break;
                }
            }
            TokenKind::Number(s)
        } else if c == '"' {
            advance(&mut i, &mut line, &mut column, c);
            let mut s = String::new();
            loop {
                let Some(&d) = chars.get(i) else {
                    return Err(ParseError::new(
                        start_line,
                        start_column,
                        "string is not closed before the end of the file",
                    ));
                };
                advance(&mut i, &mut line, &mut column, d);
                match d {
                    '"' => break,
                    '\\' if matches!(chars.get(i), Some('"' | '\\')) => {
                        s.push(chars[i]);
                        let c = chars[i];
                        advance(&mut i, &mut line, &mut column, c);
                    }
                    _ => s.push(d),
                }
            }
            TokenKind::Str(s)
        } else if ":|@+-()[],;".contains(c) {
            advance(&mut i, &mut line, &mut column, c);
            TokenKind::Punct(c)
        } else {
            return Err(ParseError::new(
                line,
                column,
                format!("unexpected character '{c}'"),
            ));
        };
        tokens.push(Token {
            kind,
            line: start_line,
            column: start_column,
        });
    }
    Ok(tokens)
}
