//! The byte stream to the firmware: a serial port or TCP.
use std::io::{self, Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::time::Duration;

use anyhow::{anyhow, bail, Context, Result};

/// A byte stream to the firmware.
pub trait Link: Send {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// Reads what has arrived, waiting at most `timeout`. `Ok(0)`: the other end closed;
    /// nothing within the timeout is an error of kind `TimedOut` or `WouldBlock`.
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize>;
}

impl Link for TcpStream {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.write_all(bytes)?;
        self.flush()
    }
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        self.set_read_timeout(Some(timeout.max(Duration::from_millis(1))))?;
        // Linux delays an ACK up to 40 ms. A peer that writes byte by byte with Nagle on
        // (QEMU's UART socket) holds the rest of every reply until that ACK: 43 ms a `ping`.
        // Quick ACKs are not sticky (the kernel leaves the mode by itself): set before every
        // read. Nagle's batching of a bulk transfer stays (unlike `nodelay=on` at QEMU).
        #[cfg(target_os = "linux")]
        socket2::SockRef::from(&*self).set_tcp_quickack(true).ok();
        self.read(buf)
    }
}

struct Serial(Box<dyn serialport::SerialPort>);

impl Link for Serial {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.0.write_all(bytes)?;
        self.0.flush()
    }
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        self.0
            .set_timeout(timeout.max(Duration::from_millis(1)))
            .map_err(io::Error::from)?;
        self.0.read(buf)
    }
}

/// Opens a TCP connection (the address may be a host name).
pub fn connect_tcp(addr: &str, timeout: Duration) -> Result<TcpStream> {
    let addrs: Vec<_> = addr
        .to_socket_addrs()
        .with_context(|| format!("--tcp {addr}: not a host:port address"))?
        .collect();
    let mut last = None;
    for a in &addrs {
        match TcpStream::connect_timeout(a, timeout) {
            Ok(s) => {
                s.set_nodelay(true).ok();
                return Ok(s);
            }
            Err(e) => last = Some(e),
        }
    }
    match last {
        Some(e) => Err(anyhow!("--tcp {addr}: cannot connect: {e}")),
        None => bail!("--tcp {addr}: the name resolves to no address"),
    }
}

/// Opens a serial port, 8N1, no flow control, and drops anything already received.
pub fn open_serial(path: &str, baud: u32, timeout: Duration) -> Result<Box<dyn Link>> {
    let port = serialport::new(path, baud)
        .timeout(timeout)
        .open()
        .with_context(|| format!("--port {path}: cannot open at {baud} Bd"))?;
    port.clear(serialport::ClearBuffer::Input).ok();
    Ok(Box::new(Serial(port)))
}
