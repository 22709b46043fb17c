//! How a server started with port 0 tells its parent where it listens: once bound, it prints one
//! line ending in `listening on ADDR` on stdout; the parent reads that line, never guesses a free
//! port (a port found by binding and dropping may be taken before the child binds it).

use std::io::{self, BufRead, BufReader, Read, Write};
use std::net::SocketAddr;
use std::sync::mpsc;
use std::time::Duration;

const MARK: &str = "listening on ";

/// Prints `"{who} listening on {addr}"` on stdout and flushes it (the parent may be waiting).
pub fn announce(who: &str, addr: SocketAddr) -> io::Result<()> {
    let mut out = io::stdout().lock();
    writeln!(out, "{who} {MARK}{addr}")?;
    out.flush()
}

/// The address of a line written by [`announce`], if `line` is one.
pub fn parse(line: &str) -> Option<SocketAddr> {
    line.split_once(MARK)?.1.trim().parse().ok()
}

/// Reads a child's stdout until its `listening on` line and returns the address, within
/// `timeout`. Every line, that one included, is copied into `rest` by a thread that keeps
/// draining the output afterwards, so the child never blocks on a full pipe.
pub fn read_addr(
    stdout: impl Read + Send + 'static,
    mut rest: impl Write + Send + 'static,
    timeout: Duration,
) -> io::Result<SocketAddr> {
    // One address is sent, once: room for it.
    let (found, addr) = mpsc::sync_channel(1);
    std::thread::spawn(move || {
        let mut found = Some(found);
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            // One write per line: `rest` may be a log file the child's stderr also appends to,
            // and a line written in two parts can be split by a log line between them.
            let _ = rest.write_all(format!("{line}\n").as_bytes());
            if let Some(addr) = parse(&line)
                && let Some(tx) = found.take()
            {
                let _ = rest.flush();
                let _ = tx.send(addr);
            }
        }
        let _ = rest.flush();
    });
    addr.recv_timeout(timeout).map_err(|e| match e {
        mpsc::RecvTimeoutError::Timeout => io::Error::new(
            io::ErrorKind::TimedOut,
            format!("no `listening on` line within {timeout:?}"),
        ),
        mpsc::RecvTimeoutError::Disconnected => io::Error::new(
            io::ErrorKind::UnexpectedEof,
            "the output ended before a `listening on` line",
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_address_and_keeps_every_line() {
        let text = "starting\nsma listening on 127.0.0.1:4567\nlater\n";
        let (tx, rx) = mpsc::channel::<Vec<u8>>();
        struct Sink(mpsc::Sender<Vec<u8>>);
        impl Write for Sink {
            fn write(&mut self, b: &[u8]) -> io::Result<usize> {
                let _ = self.0.send(b.to_vec());
                Ok(b.len())
            }
            fn flush(&mut self) -> io::Result<()> {
                Ok(())
            }
        }
        let addr = read_addr(io::Cursor::new(text), Sink(tx), Duration::from_secs(5)).unwrap();
        assert_eq!(addr, "127.0.0.1:4567".parse().unwrap());
        let copied: Vec<u8> = rx.iter().flatten().collect();
        assert_eq!(String::from_utf8(copied).unwrap(), text);
    }

    #[test]
    fn output_without_the_line_is_an_error() {
        let e = read_addr(
            io::Cursor::new("nothing\n"),
            io::sink(),
            Duration::from_secs(5),
        );
        assert_eq!(e.unwrap_err().kind(), io::ErrorKind::UnexpectedEof);
    }
}
