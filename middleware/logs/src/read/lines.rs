//! Lines of a text log with bounded memory: a line longer than [`MAX_LINE`] is consumed
//! and reported, never stored, so a corrupt or binary file cannot make a reader grow.

use std::io::{self, BufRead};

/// Longest line kept (bytes, without the line end). Real log lines are under 500 bytes.
pub(crate) const MAX_LINE: usize = 16 * 1024;

/// One line as read.
pub(crate) enum Line<'a> {
    /// The text, without `\n` or `\r\n`.
    Text(&'a str),
    /// Not UTF-8, or longer than [`MAX_LINE`]: what is wrong.
    Bad(String),
}

/// One line as read, before it is taken as text.
pub(crate) enum RawLine<'a> {
    /// The bytes, without `\n` or `\r\n`.
    Bytes(&'a [u8]),
    /// Longer than [`MAX_LINE`] (consumed, not kept).
    TooLong,
}

impl<'a> RawLine<'a> {
    /// The line as text, or what is wrong with it.
    pub fn text(self) -> Line<'a> {
        match self {
            RawLine::TooLong => Line::Bad(format!(
                "line is longer than {MAX_LINE} bytes: not a log line"
            )),
            RawLine::Bytes(bytes) => match std::str::from_utf8(bytes) {
                Ok(text) => Line::Text(text),
                Err(_) => Line::Bad("line is not text (invalid UTF-8)".into()),
            },
        }
    }
}

/// Reads lines one by one, counting them from 1.
pub(crate) struct Lines<R> {
    input: R,
    buf: Vec<u8>,
    number: u64,
}

impl<R> Lines<R> {
    /// The number of the line last returned.
    pub fn number(&self) -> u64 {
        self.number
    }
}

impl<R: BufRead> Lines<R> {
    pub fn new(input: R) -> Self {
        Self {
            input,
            buf: Vec::new(),
            number: 0,
        }
    }

    /// The next line, `None` at the end of the input.
    pub fn next_line(&mut self) -> Option<io::Result<Line<'_>>> {
        self.next_raw().map(|r| r.map(RawLine::text))
    }

    /// The next line's bytes, `None` at the end of the input.
    pub fn next_raw(&mut self) -> Option<io::Result<RawLine<'_>>> {
        self.buf.clear();
        let mut too_long = false;
        let mut any = false;
        loop {
            let available = match self.input.fill_buf() {
                Ok(bytes) => bytes,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Some(Err(e)),
            };
            if available.is_empty() {
                if !any {
                    return None;
                }
                break;
            }
            any = true;
            let (chunk, used, done) = match memchr::memchr(b'\n', available) {
                Some(i) => (&available[..i], i + 1, true),
                None => (available, available.len(), false),
            };
            if !too_long {
                if self.buf.len() + chunk.len() > MAX_LINE {
                    too_long = true;
                    self.buf.clear();
                } else {
                    self.buf.extend_from_slice(chunk);
                }
            }
            self.input.consume(used);
            if done {
                break;
            }
        }
        self.number += 1;
        if too_long {
            return Some(Ok(RawLine::TooLong));
        }
        if self.buf.last() == Some(&b'\r') {
            self.buf.pop();
        }
        Some(Ok(RawLine::Bytes(&self.buf)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn collect(input: &[u8]) -> Vec<String> {
        let mut lines = Lines::new(input);
        let mut out = Vec::new();
        while let Some(line) = lines.next_line() {
            out.push(match line.unwrap() {
                Line::Text(t) => t.to_string(),
                Line::Bad(why) => format!("BAD {why}"),
            });
        }
        out
    }

    #[test]
    fn line_ends_and_limits() {
        assert!(collect(b"").is_empty());
        assert_eq!(collect(b"a\r\nb\n\nc"), ["a", "b", "", "c"]);
        assert_eq!(collect(b"\n"), [""]);
        assert_eq!(
            collect(b"x\xFFy\nz\n")[0],
            "BAD line is not text (invalid UTF-8)"
        );
        let mut long = vec![b'a'; MAX_LINE + 1];
        long.extend_from_slice(b"\nok\n");
        let got = collect(&long);
        assert!(got[0].starts_with("BAD line is longer"));
        assert_eq!(got[1], "ok");
    }
}
