//! A pseudo-terminal pair for the serial tests: the tools open the slave by its path, as they would open
//! `/dev/ttyACM0`; the simulated firmware of `magcal-mockhw` owns the master. Dropping the master is unplugging the
//! board. The flight-controller twin runs on one too, or over UDP.

#![allow(dead_code, reason = "each test binary uses a different part")]

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::OwnedFd;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::{self, JoinHandle};
use std::time::Duration;

use magcal_app::device::{DeviceSpec, MavlinkPort};
use magcal_autopilot::{Connection, UdpPort, read_all};
use magcal_mockhw::autopilot::{AutopilotTwin, TwinConfig, TwinReport};
use magcal_mockhw::firmware::{FirmwareConfig, FirmwareReport, MotionCalFirmware};
use nix::fcntl::{FcntlArg, FdFlag, OFlag, fcntl};
use nix::pty::openpty;
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};
use nix::unistd::ttyname;

/// The two ends of a pseudo-terminal.
pub struct Pty {
    /// The board's end (raw, non-blocking).
    pub master: File,
    /// What the tools open.
    pub slave_path: String,
    /// Held open so the line stays up between the tools' runs.
    _slave: OwnedFd,
}

/// Opens a pseudo-terminal pair.
pub fn open() -> Pty {
    let pty = openpty(None, None).expect("openpty");
    let mut termios = tcgetattr(&pty.master).expect("tcgetattr");
    cfmakeraw(&mut termios);
    tcsetattr(&pty.master, SetArg::TCSANOW, &termios).expect("raw mode");
    fcntl(&pty.master, FcntlArg::F_SETFL(OFlag::O_NONBLOCK)).expect("non-blocking master");
    // The tools run as child processes: they must not inherit the board's end (or the line never hangs up).
    for fd in [&pty.master, &pty.slave] {
        fcntl(fd, FcntlArg::F_SETFD(FdFlag::FD_CLOEXEC)).expect("close-on-exec");
    }
    let slave_path = ttyname(&pty.slave)
        .expect("slave path")
        .to_str()
        .expect("utf-8 path")
        .to_owned();
    Pty {
        master: File::from(pty.master),
        slave_path,
        _slave: pty.slave,
    }
}

/// Runs the firmware on `master` in a thread until it unplugs itself or `stop` is set.
pub fn firmware(
    master: File,
    config: FirmwareConfig,
    stop: Arc<AtomicBool>,
) -> JoinHandle<FirmwareReport> {
    thread::spawn(move || {
        MotionCalFirmware::new(master, config)
            .expect("a valid bench")
            .run(|| stop.load(Ordering::Relaxed))
    })
}

/// A flight-controller twin running in a thread, on a pseudo-terminal or over UDP.
pub struct Twin {
    /// What follows `mavlink:` in a device string: the pseudo-terminal's path (the tools open it as they would
    /// `/dev/ttyACM0`), or `udp:HOST:PORT`.
    pub path: String,
    /// The pseudo-terminal, when on one.
    pty: Option<Pty>,
    stop: Arc<AtomicBool>,
    thread: JoinHandle<TwinReport>,
}

impl Twin {
    /// Starts the twin of `config` on a pseudo-terminal.
    pub fn start(config: TwinConfig) -> Twin {
        let pty = open();
        let master = pty.master.try_clone().unwrap();
        Twin::run(master, config, pty.slave_path.clone(), Some(pty))
    }

    /// Starts the twin of `config` over UDP on 127.0.0.1: listening on a port of its own, as a telemetry router's
    /// server endpoint (the tools, finding the port taken, send to it first), or sending to a free port the tools
    /// then listen on, as a simulator does.
    pub fn start_udp(config: TwinConfig, listens: bool) -> Twin {
        let (port, addr) = if listens {
            let port = UdpPort::listen("127.0.0.1:0".parse().unwrap()).unwrap();
            let addr = port.local_addr().unwrap();
            (port, addr)
        } else {
            let addr = std::net::UdpSocket::bind("127.0.0.1:0")
                .unwrap()
                .local_addr()
                .unwrap();
            (UdpPort::connect(addr).unwrap(), addr)
        };
        Twin::run(port, config, format!("udp:{addr}"), None)
    }

    fn run(
        port: impl Read + Write + Send + 'static,
        config: TwinConfig,
        path: String,
        pty: Option<Pty>,
    ) -> Twin {
        let twin = AutopilotTwin::new(port, config).unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = thread::spawn(move || twin.run(|| flag.load(Ordering::Relaxed)));
        Twin {
            path,
            pty,
            stop,
            thread,
        }
    }

    /// A ground station's connection to the twin: its pseudo-terminal opened, or its UDP port as the tools open it.
    pub fn connect(&self) -> Connection<Box<dyn MavlinkPort>> {
        let port: Box<dyn MavlinkPort> = if self.pty.is_some() {
            Box::new(
                std::fs::OpenOptions::new()
                    .read(true)
                    .write(true)
                    .open(&self.path)
                    .unwrap(),
            )
        } else {
            let Ok(DeviceSpec::Mavlink { link, .. }) = format!("mavlink:{}", self.path).parse()
            else {
                panic!("{} is no MAVLink device", self.path)
            };
            link.open().unwrap()
        };
        Connection::new(port, &self.path)
    }

    /// Reads parameters as a ground station does, on the twin's port (the twin streams, so reads never wait long).
    pub fn read(&self, names: &[&str]) -> Vec<(String, f64)> {
        let mut conn = self.connect();
        conn.wait_heartbeat(Duration::from_secs(5), None).unwrap();
        read_all(&mut conn, names)
            .unwrap()
            .into_iter()
            .map(|p| (p.name, p.value))
            .collect()
    }

    /// Asserts that the twin, read as a ground station reads it, holds the exported parameters `want` (`who` names
    /// the case in a failure).
    pub fn assert_holds(&self, want: &[(String, f64)], who: &str) {
        let names: Vec<&str> = want.iter().map(|(n, _)| n.as_str()).collect();
        for ((name, value), (_, held)) in want.iter().zip(self.read(&names)) {
            assert!(
                same(name, held, *value),
                "{who} {name}: holds {held}, exported {value}"
            );
        }
    }

    /// Stops the twin and returns what it saw.
    pub fn finish(self) -> TwinReport {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.join().unwrap()
    }
}

/// Whether `held` (a float the autopilot holds) is `exported` (printed with 3, 6 or 9 decimals).
pub fn same(name: &str, held: f64, exported: f64) -> bool {
    let printed = if name.starts_with("COMPASS_OFS") {
        5e-4
    } else if name.starts_with("COMPASS_") {
        5e-7
    } else {
        5e-10
    };
    (held - exported).abs() <= printed + 1e-6 * exported.abs().max(1e-3)
}
