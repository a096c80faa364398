//! Terminal output shared by the project's command-line programs (`virtual-car` here, and
//! `autoplug`, which builds on this crate).

use std::io::{self, Write};

/// Standard output that outlives its reader: once the reader has gone away (`... | head`),
/// the rest of the output is dropped and the program goes on, so every scenario still
/// writes its files, a gateway still closes its trips and a flash still finishes. Rust
/// ignores SIGPIPE, so without this every later write would fail (and `print!` panic).
/// Any other write error is passed on.
pub struct ReaderMayLeave<W: Write> {
    inner: W,
    gone: bool,
}

impl<W: Write> ReaderMayLeave<W> {
    /// Output to `inner` (in practice standard output, locked).
    pub fn new(inner: W) -> Self {
        Self { inner, gone: false }
    }

    /// Whether the reader has gone away (everything since was dropped).
    pub fn reader_gone(&self) -> bool {
        self.gone
    }

    fn absorb<T>(&mut self, result: io::Result<T>, instead: T) -> io::Result<T> {
        match result {
            Err(e) if e.kind() == io::ErrorKind::BrokenPipe => {
                self.gone = true;
                Ok(instead)
            }
            other => other,
        }
    }
}

impl<W: Write> Write for ReaderMayLeave<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if self.gone {
            return Ok(buf.len());
        }
        let result = self.inner.write(buf);
        self.absorb(result, buf.len())
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        if self.gone {
            return Ok(());
        }
        let result = self.inner.write_all(buf);
        self.absorb(result, ())
    }

    fn flush(&mut self) -> io::Result<()> {
        if self.gone {
            return Ok(());
        }
        let result = self.inner.flush();
        self.absorb(result, ())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Takes `open` bytes, then fails every write with `then`.
    struct Pipe {
        taken: Vec<u8>,
        open: usize,
        then: io::ErrorKind,
        writes_after: usize,
    }

    impl Write for Pipe {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            if self.taken.len() >= self.open {
                self.writes_after += 1;
                return Err(self.then.into());
            }
            let n = buf.len().min(self.open - self.taken.len());
            self.taken.extend_from_slice(&buf[..n]);
            Ok(n)
        }

        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    fn pipe(open: usize, then: io::ErrorKind) -> Pipe {
        Pipe {
            taken: Vec::new(),
            open,
            then,
            writes_after: 0,
        }
    }

    #[test]
    fn a_reader_gone_drops_the_rest_and_is_asked_no_more() {
        let mut out = ReaderMayLeave::new(pipe(4, io::ErrorKind::BrokenPipe));
        writeln!(out, "first line").unwrap();
        assert!(out.reader_gone());
        writeln!(out, "second line").unwrap();
        out.flush().unwrap();
        assert_eq!(out.inner.taken, b"firs");
        assert_eq!(out.inner.writes_after, 1, "asked once, then never again");
    }

    #[test]
    fn other_write_errors_are_passed_on() {
        let mut out = ReaderMayLeave::new(pipe(0, io::ErrorKind::StorageFull));
        let error = writeln!(out, "x").unwrap_err();
        assert_eq!(error.kind(), io::ErrorKind::StorageFull);
        assert!(!out.reader_gone());
    }
}
