//! The recorder's framed binary transfer (`rec bin`, issue 17 item 2) between the host's
//! reader (`hal_sim::serial::bulk::read_bin`) and the firmware's own executor and
//! `stream_bin`, over an in-process link that can damage the bytes coming back: a clean
//! link gives every frame bit for bit in one pass; a link that damages bytes still gives
//! every frame bit for bit, the damaged packets asked for again; a link that damages every
//! packet fails the transfer, and nothing damaged is ever taken as data.
use std::collections::VecDeque;
use std::io;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use hal_sim::serial::bulk::{read_bin, shortest};
use hal_sim::serial::{Client, Link};
use piezo_core::command::{self, LineBuffer};
use piezo_core::firmware::{c, Ctl, OnChip, SAMPLE_HZ};

/// The firmware's control state behind a link that damages one byte in `one_in` of the
/// replies to `rec bin` (0: none), from a fixed pseudo-random sequence.
struct Fake {
    ctl: Ctl<OnChip>,
    lb: LineBuffer,
    out: VecDeque<u8>,
    one_in: u64,
    rng: u64,
    in_bin: bool,
    /// Bytes damaged so far.
    hits: usize,
    /// The stage's position (um) and the last DAC code.
    y: f64,
    dac: i32,
}

impl Fake {
    /// A finished capture of `frames` frames of four channels of a closed loop tracking a
    /// sine (every value distinct enough to catch a misplaced frame).
    fn new(frames: usize, one_in: u64) -> Self {
        let mut f = Self::armed(frames, one_in);
        f.run(frames + 10);
        assert_eq!(
            f.ctl.answer("rec status").as_str(),
            format!("ok rec done {frames}")
        );
        f
    }

    /// The same loop with the capture armed and no period run yet.
    fn armed(frames: usize, one_in: u64) -> Self {
        let mut ctl = Ctl::<OnChip>::new(c(SAMPLE_HZ as f64));
        for line in [
            "wave sine 5 300 10",
            "mode ff+pid",
            "rec sel ref_um y_um u_volts dac_code",
        ] {
            assert!(ctl.answer(line).as_str().starts_with("ok"), "{line}");
        }
        let len = format!("rec len {frames}");
        assert_eq!(
            ctl.answer(&len).as_str(),
            format!("ok rec len {frames} of 4096")
        );
        assert_eq!(ctl.answer("rec arm").as_str(), "ok");
        Self {
            ctl,
            lb: LineBuffer::new(),
            out: VecDeque::new(),
            one_in,
            rng: 0x9E37_79B9_7F4A_7C15,
            in_bin: false,
            hits: 0,
            y: 0.0,
            dac: 0,
        }
    }

    /// `periods` control periods of the loop against a first-order stage.
    fn run(&mut self, periods: usize) {
        for _ in 0..periods {
            let volts = self.dac as f64 * 150.0 / 4095.0;
            self.y += 0.3 * (0.16 * volts - self.y);
            let code = (self.y * 546.125 + 5461.25).clamp(0.0, 65535.0) as i32;
            [self.dac] = self.ctl.lp.step([code]);
            self.ctl.record([code], [self.dac]);
        }
    }

    fn expected(&self) -> Vec<Vec<f64>> {
        (0..self.ctl.rec.len())
            .map(|i| {
                self.ctl
                    .rec
                    .frame(i)
                    .unwrap()
                    .iter()
                    .map(|&v| shortest(v))
                    .collect()
            })
            .collect()
    }

    fn next(&mut self) -> u64 {
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 7;
        self.rng ^= self.rng << 17;
        self.rng
    }

    fn answer(&mut self, line: Result<&[u8], command::Error>) {
        self.ctl.serve(line, &mut self.out);
    }
}

impl Link for Fake {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        for &b in bytes {
            if let Some(line) = self.lb.push(b) {
                let line: Result<Vec<u8>, command::Error> = line.map(<[u8]>::to_vec);
                self.in_bin = matches!(&line, Ok(l) if l.starts_with(b"rec bin"));
                self.answer(line.as_deref().map_err(|e| *e));
            }
        }
        Ok(())
    }

    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        if self.out.is_empty() {
            std::thread::sleep(timeout.min(Duration::from_millis(1)));
            return Err(io::ErrorKind::TimedOut.into());
        }
        let n = buf.len().min(self.out.len()).min(61);
        for b in buf.iter_mut().take(n) {
            *b = self.out.pop_front().unwrap();
            if self.in_bin && self.one_in > 0 && self.next().is_multiple_of(self.one_in) {
                // Any other value, zero included (a split packet).
                *b ^= (self.next() % 255 + 1) as u8;
                self.hits += 1;
            }
        }
        Ok(n)
    }
}

/// A fake the test keeps a hold of while the client talks to it (to run periods between
/// reads).
struct Held(Arc<Mutex<Fake>>);

impl Link for Held {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.0.lock().unwrap().send(bytes)
    }
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        self.0.lock().unwrap().recv(buf, timeout)
    }
}

/// A client over `fake`, with a short reply timeout (a packet whose delimiter was damaged
/// is waited for that long).
fn client(fake: Fake) -> Client {
    Client::new(Box::new(fake), Duration::from_millis(300))
}

#[test]
fn a_clean_link_gives_every_frame_in_one_pass() {
    let fake = Fake::new(4000, 0);
    let want = fake.expected();
    let mut c = client(fake);
    let (got, st) = read_bin(&mut c, 0, 4000, 4).unwrap();
    assert_eq!(got, want);
    assert_eq!((st.damaged, st.requests, st.packets), (0, 1, 125));
    // A part of the capture, and the text `rec read` beside it.
    let (part, _) = read_bin(&mut c, 1000, 70, 4).unwrap();
    assert_eq!(part, want[1000..1070]);
    let r = c.raw("rec read 1000 2").unwrap();
    assert_eq!(r.data.len(), 2);
    assert!(r.data[0].starts_with("1000 "));
    // Beyond the capture: the firmware's err 12, not damage.
    let e = read_bin(&mut c, 4000, 1, 4).unwrap_err();
    assert!(e.to_string().contains("error 12"), "{e}");
}

#[test]
fn damaged_bytes_are_found_and_their_frames_asked_for_again() {
    // About one damaged byte per 4 kB of `rec bin` replies: several packets hit.
    let fake = Fake::new(4096, 4000);
    let want = fake.expected();
    let mut c = client(fake);
    let (got, st) = read_bin(&mut c, 0, 4096, 4).unwrap();
    assert_eq!(got.len(), want.len());
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        assert_eq!(g, w, "frame {i}");
    }
    eprintln!("damaged link: {st:?}");
    assert!(
        st.damaged >= 3,
        "the link damaged too little to test anything: {st:?}"
    );
    assert!(st.requests > 1, "{st:?}");
}

#[test]
fn a_link_that_damages_every_packet_fails_and_accepts_nothing_damaged() {
    // One byte in 40: every packet (up to 528 bytes) is hit with near certainty.
    let fake = Fake::new(1024, 40);
    let mut c = client(fake);
    let e = read_bin(&mut c, 0, 1024, 4).unwrap_err();
    assert!(e.to_string().contains("still damaged"), "{e}");
}

/// The console's scope streams a capture: from the trigger on, the frames in place are read
/// while it fills, and they are the frames of the finished capture.
#[test]
fn a_capture_is_read_while_it_fills() {
    let fake = Arc::new(Mutex::new(Fake::armed(4000, 0)));
    let mut c = Client::new(Box::new(Held(fake.clone())), Duration::from_millis(300));
    // Nothing before the trigger (`now`: the first frame).
    let e = read_bin(&mut c, 0, 1, 4).unwrap_err();
    assert!(e.to_string().contains("error 12"), "{e}");
    fake.lock().unwrap().run(1500);
    assert_eq!(c.rec_status().unwrap(), ("triggered".to_string(), 1500));
    let (first, _) = read_bin(&mut c, 0, 1500, 4).unwrap();
    // Not beyond what is in place.
    let e = read_bin(&mut c, 1500, 1, 4).unwrap_err();
    assert!(e.to_string().contains("error 12"), "{e}");
    fake.lock().unwrap().run(1000);
    let (second, _) = read_bin(&mut c, 1500, 1000, 4).unwrap();
    fake.lock().unwrap().run(1510);
    assert_eq!(c.rec_status().unwrap(), ("done".to_string(), 4000));
    let (rest, _) = read_bin(&mut c, 2500, 1500, 4).unwrap();
    let streamed: Vec<Vec<f64>> = [first, second, rest].concat();
    assert_eq!(streamed, fake.lock().unwrap().expected());
}
