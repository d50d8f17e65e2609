//! Data recorder: fixed-size ring buffer of selected signals with a trigger.
//!
//! `CH` channels over the frames of a storage the caller supplies (an array, or a board's
//! RAM region), no allocation, O(1) per sample, no panic. A capture is `n` frames, any
//! length up to the storage's (the firmware's `rec len`). Each channel is
//! one [`Signal`] of the control loop. A capture is armed, waits for its [`Trigger`] while
//! keeping the last `pre` frames (pre-trigger history), then records until the buffer holds
//! `pre` frames before the trigger, the trigger frame and `N - pre - 1` frames after it.
//! With a divider `d` ([`Recorder::set_divider`]) every `d`-th period is a frame, so the
//! buffer spans `d` times longer (a whole XY scan); the trigger sees those frames only.

/// Largest recorder divider (1000: 10.24 s of frames at 100 kHz).
pub const MAX_DIVIDER: u32 = 1000;

/// The signals of one control period the recorder can select.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Signal {
    /// Reference position (um).
    RefUm,
    /// Measured position (um).
    YUm,
    /// Tracking error `ref - y` (um).
    ErrorUm,
    /// Feedforward voltage (V).
    FfVolts,
    /// Applied actuator voltage after limits (V).
    UVolts,
    /// Raw ADC code.
    AdcCode,
    /// DAC code written.
    DacCode,
    /// The same seven signals of the second axis (X/Y scanners; the names above are axis 0).
    RefUm1,
    YUm1,
    ErrorUm1,
    FfVolts1,
    UVolts1,
    AdcCode1,
    DacCode1,
}

impl Signal {
    /// Number of signals; the firmware fills a `[T; Signal::COUNT]` per period.
    pub const COUNT: usize = 2 * Self::PER_AXIS;
    /// Signals per axis: axis `a`'s signals are indices `a * PER_AXIS ..`, in the order
    /// of axis 0's.
    pub const PER_AXIS: usize = 7;
    pub const ALL: [Signal; Signal::COUNT] = [
        Signal::RefUm,
        Signal::YUm,
        Signal::ErrorUm,
        Signal::FfVolts,
        Signal::UVolts,
        Signal::AdcCode,
        Signal::DacCode,
        Signal::RefUm1,
        Signal::YUm1,
        Signal::ErrorUm1,
        Signal::FfVolts1,
        Signal::UVolts1,
        Signal::AdcCode1,
        Signal::DacCode1,
    ];

    /// The axis the signal belongs to (0 or 1).
    pub fn axis(self) -> usize {
        self.index() / Self::PER_AXIS
    }

    /// Index into the per-period signal array.
    pub fn index(self) -> usize {
        self as usize
    }

    pub fn name(self) -> &'static str {
        match self {
            Signal::RefUm => "ref_um",
            Signal::YUm => "y_um",
            Signal::ErrorUm => "error_um",
            Signal::FfVolts => "ff_volts",
            Signal::UVolts => "u_volts",
            Signal::AdcCode => "adc_code",
            Signal::DacCode => "dac_code",
            Signal::RefUm1 => "ref1_um",
            Signal::YUm1 => "y1_um",
            Signal::ErrorUm1 => "error1_um",
            Signal::FfVolts1 => "ff1_volts",
            Signal::UVolts1 => "u1_volts",
            Signal::AdcCode1 => "adc1_code",
            Signal::DacCode1 => "dac1_code",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }
}

/// When a capture starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Trigger<T> {
    /// As soon as the pre-trigger history is full.
    Now,
    /// Channel goes from below `level` to at or above it.
    Rising { channel: usize, level: T },
    /// Channel goes from above `level` to at or below it.
    Falling { channel: usize, level: T },
    /// Either crossing.
    Level { channel: usize, level: T },
}

/// What the recorder is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum State {
    /// Not recording (never armed or stopped).
    Idle,
    /// Recording history, waiting for the trigger.
    Armed,
    /// Trigger seen, recording the rest.
    Triggered,
    /// A complete capture is ready to read.
    Done,
}

impl State {
    pub fn name(self) -> &'static str {
        match self {
            State::Idle => "idle",
            State::Armed => "armed",
            State::Triggered => "triggered",
            State::Done => "done",
        }
    }
}

/// A bad recorder configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConfigError {
    /// Trigger channel is not one of the `CH` channels.
    NoSuchChannel,
    /// Pre-trigger length must be below the buffer length `N`.
    PreTooLong,
    /// The capture cannot be reconfigured while armed or triggered.
    Busy,
    /// The divider must be in 1..=[`MAX_DIVIDER`].
    BadDivider,
    /// The capture length must be in 1..= the recorder's capacity.
    BadLength,
}

impl ConfigError {
    pub fn message(self) -> &'static str {
        match self {
            ConfigError::NoSuchChannel => "trigger channel out of range",
            ConfigError::PreTooLong => "pre-trigger length must be below the buffer length",
            ConfigError::Busy => "recorder is capturing; stop it first",
            ConfigError::BadDivider => "divider must be in 1..=1000",
            ConfigError::BadLength => "capture length must be in 1..=the capacity",
        }
    }
}

/// Ring buffer of `CH` channels over the frames of its storage `B` (an array
/// [`ArrayRecorder`], or a `&'static mut` slice a board places in the RAM it has: the H743's
/// AXI SRAM); a capture uses the first [`Recorder::capture_len`] of them (all by default,
/// [`Recorder::set_capture_len`]).
#[derive(Debug, Clone)]
pub struct Recorder<T, const CH: usize, B> {
    buf: B,
    /// Frames per capture (1 ..= the storage's frames; 0 only for an empty storage).
    n: usize,
    /// Which signal each channel records.
    channels: [Signal; CH],
    trigger: Trigger<T>,
    pre: usize,
    state: State,
    /// Next slot to write.
    head: usize,
    /// Frames written since arming (saturates at n).
    filled: usize,
    /// Frames still to record after the trigger.
    post_left: usize,
    /// Trigger channel value of the previous frame (edge detection).
    prev: Option<T>,
    /// Every `div`-th period is a frame (>= 1).
    div: u32,
    /// Periods to skip before the next frame.
    skip: u32,
}

/// A recorder over an array of `N` frames.
pub type ArrayRecorder<T, const CH: usize, const N: usize> = Recorder<T, CH, [[T; CH]; N]>;

impl<T: Copy + Default + PartialOrd, const CH: usize, const N: usize> Default
    for ArrayRecorder<T, CH, N>
{
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Copy + Default + PartialOrd, const CH: usize, const N: usize> ArrayRecorder<T, CH, N> {
    const NONEMPTY: () = assert!(N > 0 && CH > 0, "recorder needs N > 0 and CH > 0");

    /// Idle recorder over an array; channels default to the first signals, trigger
    /// [`Trigger::Now`].
    pub fn new() -> Self {
        #[allow(clippy::let_unit_value)]
        let _ = Self::NONEMPTY;
        Self::with_storage([[T::default(); CH]; N])
    }
}

impl<T, const CH: usize, B> Recorder<T, CH, B>
where
    T: Copy + Default + PartialOrd,
    B: AsRef<[[T; CH]]> + AsMut<[[T; CH]]>,
{
    /// Idle recorder over `buf` (its frames are the capacity); channels default to the
    /// first signals, trigger [`Trigger::Now`].
    pub fn with_storage(buf: B) -> Self {
        let mut channels = [Signal::RefUm; CH];
        for (c, s) in channels.iter_mut().zip(Signal::ALL) {
            *c = s;
        }
        let n = buf.as_ref().len();
        Self {
            buf,
            n,
            channels,
            trigger: Trigger::Now,
            pre: 0,
            state: State::Idle,
            head: 0,
            filled: 0,
            post_left: 0,
            prev: None,
            div: 1,
            skip: 0,
        }
    }

    /// Frames the storage holds.
    pub fn capacity(&self) -> usize {
        self.buf.as_ref().len()
    }

    /// Frames per capture.
    pub fn capture_len(&self) -> usize {
        self.n
    }

    /// Frames per capture, 1 ..= [`Recorder::capacity`] (while idle or done; a finished
    /// capture is dropped). The pre-trigger length must stay below it.
    pub fn set_capture_len(&mut self, n: usize) -> Result<(), ConfigError> {
        self.idle_or_done()?;
        if n == 0 || n > self.capacity() {
            return Err(ConfigError::BadLength);
        }
        if self.pre >= n {
            return Err(ConfigError::PreTooLong);
        }
        self.n = n;
        self.state = State::Idle;
        Ok(())
    }

    /// Records every `div`-th period (1..=[`MAX_DIVIDER`]; 1: every period).
    pub fn set_divider(&mut self, div: u32) -> Result<(), ConfigError> {
        self.idle_or_done()?;
        if !(1..=MAX_DIVIDER).contains(&div) {
            return Err(ConfigError::BadDivider);
        }
        self.div = div;
        Ok(())
    }

    /// Periods per frame.
    pub fn divider(&self) -> u32 {
        self.div
    }

    pub fn state(&self) -> State {
        self.state
    }

    pub fn channels(&self) -> &[Signal; CH] {
        &self.channels
    }

    /// Frames available to [`Recorder::frame`] (the capture length when done, else 0).
    pub fn len(&self) -> usize {
        if self.state == State::Done {
            self.n
        } else {
            0
        }
    }

    /// Frames of the capture in place so far, for progress reports: those held while
    /// armed (at most n), n less the frames still due once triggered, n when done.
    pub fn progress(&self) -> usize {
        match self.state {
            State::Idle => 0,
            State::Armed => self.filled,
            State::Triggered => self.n - self.post_left.min(self.n),
            State::Done => self.n,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn idle_or_done(&self) -> Result<(), ConfigError> {
        match self.state {
            State::Idle | State::Done => Ok(()),
            _ => Err(ConfigError::Busy),
        }
    }

    /// Selects the signals of the first `signals.len()` channels (extra ones are ignored).
    pub fn select(&mut self, signals: &[Signal]) -> Result<(), ConfigError> {
        self.idle_or_done()?;
        for (c, &s) in self.channels.iter_mut().zip(signals) {
            *c = s;
        }
        Ok(())
    }

    /// Sets the trigger and the pre-trigger length (frames kept before the trigger).
    pub fn set_trigger(&mut self, trigger: Trigger<T>, pre: usize) -> Result<(), ConfigError> {
        self.idle_or_done()?;
        match trigger {
            Trigger::Now => {}
            Trigger::Rising { channel, .. }
            | Trigger::Falling { channel, .. }
            | Trigger::Level { channel, .. } => {
                if channel >= CH {
                    return Err(ConfigError::NoSuchChannel);
                }
            }
        }
        if pre >= self.n {
            return Err(ConfigError::PreTooLong);
        }
        self.trigger = trigger;
        self.pre = pre;
        Ok(())
    }

    /// Starts a capture (discarding the previous one).
    pub fn arm(&mut self) {
        self.state = State::Armed;
        self.head = 0;
        self.filled = 0;
        self.prev = None;
        self.skip = 0;
    }

    /// Aborts a capture.
    pub fn stop(&mut self) {
        if self.state != State::Done {
            self.state = State::Idle;
        }
    }

    /// Records one control period; `signals` is indexed by [`Signal::index`] (a missing
    /// entry records `T::default()`). O(1), no panic.
    #[inline]
    pub fn push(&mut self, signals: &[T]) {
        if !matches!(self.state, State::Armed | State::Triggered) {
            return;
        }
        if self.skip > 0 {
            self.skip -= 1;
            return;
        }
        self.skip = self.div.saturating_sub(1);
        let mut frame = [T::default(); CH];
        for (v, s) in frame.iter_mut().zip(self.channels.iter()) {
            *v = signals.get(s.index()).copied().unwrap_or_default();
        }
        let n = self.n;
        if let Some(slot) = self.buf.as_mut().get_mut(self.head) {
            *slot = frame;
        }
        self.head = if self.head + 1 >= n { 0 } else { self.head + 1 };
        self.filled = (self.filled + 1).min(n);
        match self.state {
            State::Armed => {
                // `fires` also tracks the previous value, so it runs on every frame.
                let fired = self.fires(&frame) && self.filled > self.pre;
                if fired {
                    self.post_left = n.saturating_sub(self.pre + 1);
                    self.state = if self.post_left == 0 {
                        State::Done
                    } else {
                        State::Triggered
                    };
                }
            }
            State::Triggered => {
                self.post_left = self.post_left.saturating_sub(1);
                if self.post_left == 0 {
                    self.state = State::Done;
                }
            }
            State::Idle | State::Done => {}
        }
    }

    /// Edge/level test on the trigger channel; NaN never fires.
    fn fires(&mut self, frame: &[T; CH]) -> bool {
        let (channel, level) = match self.trigger {
            Trigger::Now => return true,
            Trigger::Rising { channel, level }
            | Trigger::Falling { channel, level }
            | Trigger::Level { channel, level } => (channel, level),
        };
        let Some(&cur) = frame.get(channel) else {
            return false;
        };
        let Some(prev) = self.prev.replace(cur) else {
            return false;
        };
        let rising = prev < level && cur >= level;
        let falling = prev > level && cur <= level;
        match self.trigger {
            Trigger::Rising { .. } => rising,
            Trigger::Falling { .. } => falling,
            _ => rising || falling,
        }
    }

    /// Frame `i` of a finished capture, oldest first (the trigger is frame `pre`).
    pub fn frame(&self, i: usize) -> Option<&[T; CH]> {
        let n = self.n;
        if self.state != State::Done || i >= n {
            return None;
        }
        let k = self.head + i;
        self.buf.as_ref().get(if k >= n { k - n } else { k })
    }

    /// Frames [`Recorder::read`] gives now: the first [`Recorder::progress`] of a triggered
    /// capture, all of a finished one, none before the trigger.
    pub fn readable(&self) -> usize {
        match self.state {
            State::Triggered | State::Done => self.progress(),
            State::Idle | State::Armed => 0,
        }
    }

    /// Frame `i` of the capture, oldest first, as soon as it is in place: a capture can be
    /// read while it fills (a scope that streams), and a frame read early equals the one
    /// [`Recorder::frame`] gives when it is done. After the trigger the capture's first
    /// frame sits `post_left` slots past the head, and nothing overwrites it until the next
    /// arm.
    pub fn read(&self, i: usize) -> Option<&[T; CH]> {
        match self.state {
            State::Done => self.frame(i),
            State::Triggered if i < self.progress() => {
                let k = (self.head + self.post_left).checked_rem(self.n)? + i;
                self.buf
                    .as_ref()
                    .get(if k >= self.n { k - self.n } else { k })
            }
            _ => None,
        }
    }

    /// Index of the trigger frame in a finished capture.
    pub fn trigger_index(&self) -> usize {
        self.pre
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn signals(v: f32) -> [f32; Signal::COUNT] {
        let mut s = [0.0; Signal::COUNT];
        s[Signal::RefUm.index()] = v;
        s[Signal::YUm.index()] = -v;
        s
    }

    /// Two channels (reference, position), rising trigger at 10 on the reference, 3
    /// frames before it.
    fn rising_at_10_pre_3() -> ArrayRecorder<f32, 2, 8> {
        let mut r = ArrayRecorder::<f32, 2, 8>::new();
        r.select(&[Signal::RefUm, Signal::YUm]).unwrap();
        r.set_trigger(
            Trigger::Rising {
                channel: 0,
                level: 10.0,
            },
            3,
        )
        .unwrap();
        r
    }

    #[test]
    fn rising_edge_with_pre_trigger() {
        let mut r = rising_at_10_pre_3();
        r.arm();
        // Ramp 0, 1, 2, ...: crosses 10 at sample 10.
        for k in 0..40 {
            r.push(&signals(k as f32));
        }
        assert_eq!(r.state(), State::Done);
        assert_eq!(r.len(), 8);
        let got: Vec<f32> = (0..8).map(|i| r.frame(i).unwrap()[0]).collect();
        assert_eq!(got, vec![7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0]);
        assert_eq!(r.frame(r.trigger_index()).unwrap(), &[10.0, -10.0]);
        assert!(r.frame(8).is_none());
    }

    #[test]
    fn progress_grows_until_done() {
        let mut r = rising_at_10_pre_3();
        assert_eq!(r.progress(), 0);
        r.arm();
        let mut seen = vec![];
        for k in 0..40 {
            r.push(&signals(k as f32));
            seen.push((r.state(), r.progress()));
        }
        // Armed: the ring fills (saturating at 8) before the crossing at sample 10; then
        // the frames still due count down to done.
        assert_eq!(seen[0], (State::Armed, 1));
        assert_eq!(seen[9], (State::Armed, 8));
        assert_eq!(seen[10], (State::Triggered, 4));
        assert_eq!(seen[13], (State::Triggered, 7));
        assert_eq!(seen[14], (State::Done, 8));
        assert!(seen
            .windows(2)
            .all(|w| w[0].0 != w[1].0 || w[0].1 <= w[1].1));
    }

    #[test]
    fn falling_and_level_triggers() {
        let wave = |k: usize| 5.0 - (k as f32);
        let mut r = ArrayRecorder::<f32, 1, 4>::new();
        // Arms with `trigger` (`pre` frames before it) and records the ramp.
        let run = |r: &mut ArrayRecorder<f32, 1, 4>, trigger, pre| {
            r.set_trigger(trigger, pre).unwrap();
            r.arm();
            for k in 0..20 {
                r.push(&signals(wave(k)));
            }
        };
        let level = 0.0;
        run(&mut r, Trigger::Falling { channel: 0, level }, 1);
        assert_eq!(r.frame(1).unwrap()[0], 0.0);
        assert_eq!(r.frame(0).unwrap()[0], 1.0);

        // A rising trigger never fires on a falling ramp.
        run(&mut r, Trigger::Rising { channel: 0, level }, 1);
        assert_eq!(r.state(), State::Armed);
        assert!(r.frame(0).is_none());
        r.stop();
        run(
            &mut r,
            Trigger::Level {
                channel: 0,
                level: 0.5,
            },
            0,
        );
        assert_eq!(r.frame(0).unwrap()[0], 0.0);
    }

    #[test]
    fn nan_never_triggers_and_config_is_checked() {
        let mut r = ArrayRecorder::<f32, 1, 4>::new();
        r.set_trigger(
            Trigger::Level {
                channel: 0,
                level: 0.0,
            },
            0,
        )
        .unwrap();
        r.arm();
        for _ in 0..10 {
            r.push(&signals(f32::NAN));
        }
        assert_eq!(r.state(), State::Armed);
        assert_eq!(r.set_trigger(Trigger::Now, 0), Err(ConfigError::Busy));
        r.stop();
        assert_eq!(
            r.set_trigger(
                Trigger::Rising {
                    channel: 1,
                    level: 0.0
                },
                0
            ),
            Err(ConfigError::NoSuchChannel)
        );
        assert_eq!(r.set_trigger(Trigger::Now, 4), Err(ConfigError::PreTooLong));
    }

    #[test]
    fn divider_keeps_every_nth_period() {
        let mut r = ArrayRecorder::<f32, 1, 8>::new();
        assert_eq!(r.set_divider(0), Err(ConfigError::BadDivider));
        assert_eq!(r.set_divider(MAX_DIVIDER + 1), Err(ConfigError::BadDivider));
        r.set_divider(3).unwrap();
        r.arm();
        assert_eq!(r.set_divider(2), Err(ConfigError::Busy));
        for k in 0..100 {
            r.push(&[k as f32]);
        }
        assert_eq!(r.state(), State::Done);
        let got: Vec<f32> = (0..8).map(|i| r.frame(i).unwrap()[0]).collect();
        assert_eq!(got, [0.0, 3.0, 6.0, 9.0, 12.0, 15.0, 18.0, 21.0]);
        assert_eq!(r.divider(), 3);
    }

    #[test]
    fn capture_length_within_a_slice_storage() {
        let mut store = [[0.0f32; 1]; 16];
        let mut r = Recorder::<f32, 1, &mut [[f32; 1]]>::with_storage(&mut store[..]);
        assert_eq!((r.capacity(), r.capture_len()), (16, 16));
        assert_eq!(r.set_capture_len(0), Err(ConfigError::BadLength));
        assert_eq!(r.set_capture_len(17), Err(ConfigError::BadLength));
        r.set_capture_len(5).unwrap();
        r.arm();
        assert_eq!(r.set_capture_len(6), Err(ConfigError::Busy));
        for k in 0..20 {
            r.push(&[k as f32]);
        }
        assert_eq!((r.state(), r.len(), r.progress()), (State::Done, 5, 5));
        let got: Vec<f32> = (0..5).map(|i| r.frame(i).unwrap()[0]).collect();
        assert_eq!(got, [0.0, 1.0, 2.0, 3.0, 4.0]);
        assert!(r.frame(5).is_none());
        assert_eq!(r.set_trigger(Trigger::Now, 5), Err(ConfigError::PreTooLong));
        r.set_trigger(Trigger::Now, 4).unwrap();
        assert_eq!(r.set_capture_len(4), Err(ConfigError::PreTooLong));
        // A new length drops the finished capture.
        r.set_capture_len(16).unwrap();
        assert_eq!((r.state(), r.len()), (State::Idle, 0));
        // An empty storage never panics and never finishes.
        let mut e = Recorder::<f32, 1, &mut [[f32; 1]]>::with_storage(&mut []);
        e.arm();
        for k in 0..10 {
            e.push(&[k as f32]);
        }
        assert_eq!((e.state(), e.len()), (State::Armed, 0));
        assert!(e.frame(0).is_none());
    }

    #[test]
    fn signal_names_round_trip() {
        for (i, s) in Signal::ALL.into_iter().enumerate() {
            assert_eq!(Signal::from_name(s.name()), Some(s));
            assert_eq!(s.index(), i);
            assert_eq!(s.axis(), i / Signal::PER_AXIS);
        }
        // Axis 1 mirrors axis 0 signal by signal.
        for (a, b) in Signal::ALL.iter().zip(&Signal::ALL[Signal::PER_AXIS..]) {
            assert_eq!(a.name().replacen('_', "1_", 1), b.name());
        }
        assert_eq!(Signal::from_name("bogus"), None);
    }

    proptest! {
        /// Whatever the configuration, a finished capture holds exactly the `pre` frames
        /// before the trigger frame and the ones after it, in order.
        #[test]
        fn capture_is_a_contiguous_window(pre in 0usize..16, start in 0usize..50, len in 0usize..100) {
            let mut r = ArrayRecorder::<f32, 1, 16>::new();
            r.set_trigger(Trigger::Rising { channel: 0, level: start as f32 }, pre).unwrap();
            r.arm();
            for k in 0..len {
                r.push(&signals(k as f32));
            }
            // The ramp crosses `start` at sample `start` (a crossing needs a previous
            // sample); it counts only once `pre` frames of history exist.
            let expect_done = start >= 1 && start >= pre && len >= start + 16 - pre;
            prop_assert_eq!(r.state() == State::Done, expect_done);
            if expect_done {
                prop_assert_eq!(r.frame(pre).unwrap()[0], start as f32);
                for i in 0..16 {
                    prop_assert_eq!(r.frame(i).unwrap()[0], (start - pre + i) as f32);
                }
            }
        }

        /// A capture read while it fills (after every frame, what is readable so far)
        /// gives the frames of the finished capture, and nothing before the trigger.
        #[test]
        fn frames_read_while_filling_are_the_final_ones(
            n in 1usize..16, pre in 0usize..16, start in 1usize..40, div in 1u32..4,
        ) {
            let pre = pre % n;
            let mut r = ArrayRecorder::<f32, 2, 16>::new();
            r.set_capture_len(n).unwrap();
            r.set_divider(div).unwrap();
            // The ramp's crossing comes after `pre` frames of history, so it fires.
            let level = (start + pre * div as usize) as f32;
            r.set_trigger(Trigger::Rising { channel: 0, level }, pre).unwrap();
            r.arm();
            let mut early = vec![None; n];
            let mut k = 0;
            while r.state() != State::Done && k < 200 {
                r.push(&signals(k as f32));
                k += 1;
                prop_assert_eq!(r.readable() > 0, r.state() != State::Armed);
                prop_assert!(r.read(r.readable()).is_none() || r.state() == State::Done);
                for (i, e) in early.iter_mut().enumerate().take(r.readable()) {
                    let f = *r.read(i).unwrap();
                    prop_assert!(e.is_none_or(|e| e == f), "frame {} changed", i);
                    *e = Some(f);
                }
            }
            prop_assert_eq!(r.state(), State::Done);
            prop_assert_eq!(r.readable(), n);
            for (i, e) in early.iter().enumerate() {
                prop_assert_eq!(*e, r.frame(i).copied());
            }
        }
    }

    #[test]
    fn nothing_readable_while_armed_or_idle() {
        let mut r = rising_at_10_pre_3();
        assert_eq!((r.readable(), r.read(0)), (0, None));
        r.arm();
        for k in 0..10 {
            r.push(&signals(k as f32));
        }
        assert_eq!(r.state(), State::Armed);
        assert_eq!((r.readable(), r.read(0)), (0, None));
        r.push(&signals(10.0));
        assert_eq!(r.state(), State::Triggered);
        // The three frames before the trigger and the trigger frame.
        assert_eq!(r.readable(), 4);
        assert_eq!(r.read(3).map(|f| f[0]), Some(10.0));
        assert_eq!(r.read(4), None);
    }
}
