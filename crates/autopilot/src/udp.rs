//! MAVLink over UDP, as a byte port for [`crate::Connection`]: each write is one datagram, reads hand out the
//! datagrams' bytes in order.
//!
//! [`UdpPort::open`] binds the address when it is this machine's (a simulator or a telemetry router sending to a
//! ground station's port, as PX4 SITL and MAVProxy do to 14550) and answers whoever sent the last datagram; when the
//! address is another machine's, or its port is already taken (a router's server endpoint), it sends to that address
//! from a port of its own instead, and the caller speaks first ([`UdpPort::sends_first`]).

use std::io::{self, ErrorKind, Read, Write};
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};
use std::time::Duration;

/// The largest datagram read.
const DATAGRAM: usize = 65_536;

/// A UDP socket as a byte port; see the [module docs](self).
#[derive(Debug)]
pub struct UdpPort {
    socket: UdpSocket,
    /// Where writes go: the address sent to, or the last sender heard when listening (none heard yet: dropped).
    peer: Option<SocketAddr>,
    listening: bool,
    buf: Vec<u8>,
    /// Bytes of `buf` not yet handed out: `buf[start..end]`.
    start: usize,
    end: usize,
}

impl UdpPort {
    /// Listens on `addr` (a local address), answering the last sender.
    pub fn listen(addr: SocketAddr) -> io::Result<UdpPort> {
        UdpPort::new(UdpSocket::bind(addr)?, None, true)
    }

    /// Sends to `addr` from a port of this machine's choosing, hearing only `addr` (the socket is not connected, so
    /// that nobody listening there yet is not an error: a simulator starting later).
    pub fn connect(addr: SocketAddr) -> io::Result<UdpPort> {
        let any: SocketAddr = if addr.is_ipv4() {
            ([0, 0, 0, 0], 0).into()
        } else {
            (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
        };
        UdpPort::new(UdpSocket::bind(any)?, Some(addr), false)
    }

    /// `HOST:PORT` listened on if it is this machine's and free, else sent to (see the [module docs](self)).
    pub fn open(host_port: &str) -> io::Result<UdpPort> {
        let addr = host_port.to_socket_addrs()?.next().ok_or_else(|| {
            io::Error::new(ErrorKind::NotFound, format!("{host_port}: no address"))
        })?;
        match UdpPort::listen(addr) {
            Err(e) if matches!(e.kind(), ErrorKind::AddrNotAvailable | ErrorKind::AddrInUse) => {
                UdpPort::connect(addr)
            }
            other => other,
        }
    }

    fn new(socket: UdpSocket, peer: Option<SocketAddr>, listening: bool) -> io::Result<UdpPort> {
        socket.set_read_timeout(Some(Duration::from_millis(20)))?;
        Ok(UdpPort {
            socket,
            peer,
            listening,
            buf: vec![0; DATAGRAM],
            start: 0,
            end: 0,
        })
    }

    /// Whether the other side only answers: this port sends to an address (it must speak first).
    pub fn sends_first(&self) -> bool {
        !self.listening
    }

    /// The local address.
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }
}

impl Read for UdpPort {
    /// A datagram's bytes; `TimedOut` or `WouldBlock` after 20 ms without one.
    fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
        if self.start == self.end {
            let (n, from) = self.socket.recv_from(&mut self.buf)?;
            if self.listening {
                self.peer = Some(from);
            } else if Some(from) != self.peer {
                return Err(ErrorKind::WouldBlock.into());
            }
            (self.start, self.end) = (0, n);
        }
        let n = out.len().min(self.end - self.start);
        out[..n].copy_from_slice(&self.buf[self.start..self.start + n]);
        self.start += n;
        Ok(n)
    }
}

impl Write for UdpPort {
    /// One datagram to the peer; dropped (as a radio link would) while listening before anyone was heard.
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        match self.peer {
            Some(peer) => self.socket.send_to(bytes, peer),
            None => Ok(bytes.len()),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_listener_answers_the_last_sender_and_a_taken_port_is_sent_to() {
        let mut listener = UdpPort::open("127.0.0.1:0").unwrap();
        assert!(!listener.sends_first());
        let addr = listener.local_addr().unwrap();
        // Nobody heard yet: the write goes nowhere.
        assert_eq!(listener.write(b"lost").unwrap(), 4);
        // The port is taken: a second open sends to it.
        let mut sender = UdpPort::open(&addr.to_string()).unwrap();
        assert!(sender.sends_first());
        sender.write_all(b"hello").unwrap();
        let mut got = [0u8; 3];
        assert_eq!(listener.read(&mut got).unwrap(), 3);
        assert_eq!(&got, b"hel");
        assert_eq!(listener.read(&mut got).unwrap(), 2);
        assert_eq!(&got[..2], b"lo");
        listener.write_all(b"back").unwrap();
        let mut back = [0u8; 8];
        let n = sender.read(&mut back).unwrap();
        assert_eq!(&back[..n], b"back");
        // Nothing more: a timeout, not an end of file.
        let e = sender.read(&mut back).unwrap_err();
        assert!(matches!(
            e.kind(),
            ErrorKind::WouldBlock | ErrorKind::TimedOut
        ));
    }
}
