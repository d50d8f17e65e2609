//! Settings kept across power cycles: the settings as one versioned, checksummed record
//! ([`encode`], [`decode`]), kept in NOR flash by `sequential-storage`'s map (power-fail
//! safe: after a power loss at any point of a `save` the flash holds the old record or the
//! new one), and the `save`/`load`/`defaults` commands against the control state.
//!
//! Record (little endian): magic `PZST`, version (u16), count (u16), `count` entries of
//! (CRC-32 of the setting's name, value as f32), CRC-32 of everything before. A record is
//! refused (and nothing changed) when its magic, version, checksum or length is wrong, when
//! it names a setting this firmware does not store or lacks one it does, or when the values
//! together do not pass the same checks as `set`.

use super::control_loop::Loop;
use super::converters::converter_config;
use super::converters::Converters;
use super::execute::{get_param, PARAMS, READ_ONLY};
use super::nor::Blocking;
use super::params::Params;
use super::settings::{default_of, setting};
use super::target::{c, R};
use crate::command::Error;
use crate::pipeline::{Mode, Wave};
use crate::Real;
use core::future::Future;
use core::ops::Range;
use core::pin::pin;
use core::task::{Context, Poll, Waker};
use crc::{Crc, CRC_32_ISO_HDLC};
use embedded_storage::nor_flash::NorFlash;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

const MAGIC: [u8; 4] = *b"PZST";
/// Record layout version: bump when the layout (not the set of settings) changes.
pub const VERSION: u16 = 1;
const HEADER: usize = 8;
const ENTRY: usize = 8;
/// Entries a record can hold (the stored settings are fewer; checked by a test).
pub const MAX_SETTINGS: usize = 32;
/// The longest record.
pub const MAX_RECORD: usize = HEADER + ENTRY * MAX_SETTINGS + 4;
const CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);
/// The map key the record is stored under.
const KEY: u8 = 1;

/// The settings a record holds: every settable parameter of `get`/`set` (the converter
/// scalings and the sample rate follow from the board and are not stored).
pub fn stored() -> impl Iterator<Item = &'static str> {
    PARAMS.into_iter().filter(|n| !READ_ONLY.contains(n))
}

/// The key of a setting in a record: CRC-32 of its name.
pub fn name_key(name: &str) -> u32 {
    CRC32.checksum(name.as_bytes())
}

/// A checked record: (name key, value) pairs. Built only by [`decode`].
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    entries: [(u32, f32); MAX_SETTINGS],
    len: usize,
}

impl Record {
    /// The value stored for `name`.
    pub fn value(&self, name: &str) -> Option<f32> {
        let key = name_key(name);
        self.entries
            .iter()
            .take(self.len)
            .find(|(k, _)| *k == key)
            .map(|(_, v)| *v)
    }

    /// Number of settings in the record.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// Writes the record of `values` ((name, value) pairs, at most [`MAX_SETTINGS`]) into
/// `out`; returns its length. A non-finite value is refused ([`Error::OutOfRange`]): it
/// would write a record [`decode`] refuses (found by the `settings_record` fuzz target).
pub fn encode<'a>(
    values: impl Iterator<Item = (&'a str, f32)>,
    out: &mut [u8; MAX_RECORD],
) -> Result<usize, Error> {
    let mut n = 0usize;
    for ((name, v), slot) in values.zip(out.chunks_exact_mut(ENTRY).skip(HEADER / ENTRY)) {
        if !v.is_finite() {
            return Err(Error::OutOfRange);
        }
        let mut e = [0u8; ENTRY];
        let (k, x) = e.split_at_mut(4);
        k.copy_from_slice(&name_key(name).to_le_bytes());
        x.copy_from_slice(&v.to_le_bytes());
        slot.copy_from_slice(&e);
        n += 1;
    }
    let [m0, m1, m2, m3] = MAGIC;
    let [v0, v1] = VERSION.to_le_bytes();
    let [n0, n1] = (n as u16).to_le_bytes();
    if let Some(h) = out.first_chunk_mut::<HEADER>() {
        *h = [m0, m1, m2, m3, v0, v1, n0, n1];
    }
    let end = HEADER + ENTRY * n;
    let crc = CRC32.checksum(out.get(..end).ok_or(Error::OutOfRange)?);
    out.get_mut(end..end + 4)
        .ok_or(Error::OutOfRange)?
        .copy_from_slice(&crc.to_le_bytes());
    Ok(end + 4)
}

/// Checks a record's format (not yet its values; see [`Loop::apply_settings`]).
pub fn decode(blob: &[u8]) -> Result<Record, Error> {
    let bad = Error::BadSettings;
    let (body, crc) = blob.split_last_chunk::<4>().ok_or(bad)?;
    if CRC32.checksum(body) != u32::from_le_bytes(*crc) {
        return Err(bad);
    }
    let (head, entries) = body.split_first_chunk::<HEADER>().ok_or(bad)?;
    let [m0, m1, m2, m3, v0, v1, n0, n1] = *head;
    if [m0, m1, m2, m3] != MAGIC || u16::from_le_bytes([v0, v1]) != VERSION {
        return Err(bad);
    }
    let n = usize::from(u16::from_le_bytes([n0, n1]));
    if n > MAX_SETTINGS || entries.len() != n * ENTRY {
        return Err(bad);
    }
    let mut rec = Record {
        entries: [(0, 0.0); MAX_SETTINGS],
        len: n,
    };
    for (e, d) in entries.chunks_exact(ENTRY).zip(rec.entries.iter_mut()) {
        let (k, v) = e.split_at(4);
        let k = u32::from_le_bytes(k.try_into().map_err(|_| bad)?);
        let v = f32::from_le_bytes(v.try_into().map_err(|_| bad)?);
        if !v.is_finite() {
            return Err(bad);
        }
        *d = (k, v);
    }
    // Exactly the settings this firmware stores, each once (a stale table is refused).
    let count = stored().count();
    if n != count || stored().any(|s| rec.value(s).is_none()) {
        return Err(bad);
    }
    Ok(rec)
}

/// Runs a future of `sequential-storage` over a [`Blocking`] flash: every flash operation
/// completes at once, so the future is ready on its first poll (one poll, no loop; a
/// pending future would be a flash that waits, reported as [`Error::Flash`]).
pub fn block_on<T>(f: impl Future<Output = T>) -> Result<T, Error> {
    let mut f = pin!(f);
    match f.as_mut().poll(&mut Context::from_waker(Waker::noop())) {
        Poll::Ready(v) => Ok(v),
        Poll::Pending => Err(Error::Flash),
    }
}

/// Room for the key and the longest record, rounded up to the flash word (the map's work
/// buffer).
const WORK: usize = 512;

type NoCache = Cache<Uncached, Uncached, Uncached, u8>;

/// The settings flash: a range of whole sectors of `F` the code never runs from, holding
/// the record under one key of a `sequential-storage` map.
pub struct SettingsFlash<F: NorFlash> {
    map: MapStorage<u8, Blocking<F>, NoCache>,
    work: [u8; WORK],
}

impl<F: NorFlash> SettingsFlash<F> {
    /// `range`: at least two whole sectors of `flash`.
    pub fn new(flash: F, range: Range<u32>) -> Result<Self, Error> {
        let config = MapConfig::try_new(range).map_err(|_| Error::Flash)?;
        if F::WRITE_SIZE > WORK / 4 {
            return Err(Error::Flash);
        }
        Ok(Self {
            map: MapStorage::new(Blocking::new(flash), config, Cache::new_uncached()),
            work: [0; WORK],
        })
    }

    /// Stores `record` (replacing the one before only once it is completely written). The
    /// generic store, not `store_item`'s `dyn Value`: a call through a vtable would leave
    /// idle's stack bound unknown to the firmware safety check.
    pub fn save(&mut self, record: &[u8]) -> Result<(), Error> {
        block_on(self.map.store_item_generic(&mut self.work, &KEY, &record))?
            .map_err(|_| Error::Flash)
    }

    /// The stored record, copied into `out` (`Ok(None)`: none stored).
    pub fn load(&mut self, out: &mut [u8; MAX_RECORD]) -> Result<Option<usize>, Error> {
        let got = block_on(self.map.fetch_item::<&[u8]>(&mut self.work, &KEY))?
            .map_err(|_| Error::Flash)?;
        match got {
            None => Ok(None),
            Some(r) if r.len() <= MAX_RECORD => {
                out[..r.len()].copy_from_slice(r);
                Ok(Some(r.len()))
            }
            Some(_) => Err(Error::BadSettings),
        }
    }

    /// Erases the settings sectors (nothing stored afterwards): a board's way out of a
    /// record it cannot even read.
    pub fn erase_all(&mut self) -> Result<(), Error> {
        block_on(self.map.erase_all())?.map_err(|_| Error::Flash)
    }

    /// The flash back (tests: a reboot is a new [`SettingsFlash`] over the same flash).
    pub fn into_flash(self) -> F {
        self.map.destroy().0.flash
    }

    /// [`Self::load`] at boot: every erase refused, since an H743 sector erase (2-4 s)
    /// outlasts the boot watchdog (100 ms) and a repair `sequential-storage` starts after
    /// an interrupted save may erase a sector. `Err(Error::Flash)` with
    /// [`Self::needs_repair`] true: the repair needs that erase; [`Self::repair`] does it
    /// from idle, where the running loop feeds the watchdog.
    pub fn boot_load(&mut self, out: &mut [u8; MAX_RECORD]) -> Result<Option<usize>, Error> {
        let b = self.map.flash();
        (b.refuse_erase, b.erase_refused) = (true, false);
        let got = self.load(out);
        self.map.flash().refuse_erase = false;
        got
    }

    /// The last [`Self::boot_load`] stopped at an erase its repair needs.
    pub fn needs_repair(&mut self) -> bool {
        self.map.flash().erase_refused
    }

    /// The repair a [`Self::boot_load`] could not finish (erases allowed: idle only): a
    /// load, whose record is not installed (`load` does that); `Ok(true)` when a record is
    /// stored.
    pub fn repair(&mut self) -> Result<bool, Error> {
        let mut buf = [0u8; MAX_RECORD];
        let got = self.load(&mut buf)?;
        self.map.flash().erase_refused = false;
        Ok(got.is_some())
    }
}

/// What the boot found in the settings flash.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Boot {
    /// The stored settings are installed.
    Loaded,
    /// Nothing stored: the built-in defaults run.
    Empty,
    /// A record was there but refused (damaged, stale, invalid values) or the flash failed:
    /// the defaults run (warn the user).
    Refused(Error),
    /// An interrupted save left the flash in a state whose repair erases a sector, which
    /// boot does not do (the watchdog): the defaults run, idle repairs
    /// ([`SettingsFlash::repair`]), and `load` then installs the stored record.
    Repair,
}

impl Boot {
    /// What a boot-time install (of [`SettingsFlash::boot_load`]'s record) came to.
    pub fn of<F: NorFlash, T>(flash: &mut SettingsFlash<F>, installed: Result<T, Error>) -> Self {
        match installed {
            Ok(_) => Boot::Loaded,
            Err(_) if flash.needs_repair() => Boot::Repair,
            Err(Error::NoSettings) => Boot::Empty,
            Err(e) => Boot::Refused(e),
        }
    }
}

impl<C: Converters> Loop<C> {
    /// True when the loop drives the stage (a feedback law or the feedforward, or a moving
    /// reference), i.e. not in the safe state: `save` is refused then.
    pub fn drives_stage(&self) -> bool {
        let lp = self;
        if lp.p.state().fault.is_some() {
            return false;
        }
        let moving = (0..super::AXES).any(|a| {
            !matches!(
                lp.p.reference(a).map(|r| r.wave()),
                Some(Wave::Hold { .. }) | None
            )
        });
        lp.p.state().mode != Mode::OpenLoop || moving
    }

    /// The record of the current settings (`save`).
    pub fn settings_record(&self, out: &mut [u8; MAX_RECORD]) -> Result<usize, Error> {
        if self.drives_stage() {
            return Err(Error::Busy);
        }
        let lp = self;
        encode(
            stored().map(|n| (n, get_param(lp, n).map_or(f32::NAN, |v| v.to_f64() as f32))),
            out,
        )
    }

    /// Installs every setting of `rec` or, if any is refused, none (`load`).
    pub fn apply_settings(&mut self, rec: &Record) -> Result<(), Error> {
        let mut p = self.params;
        for name in stored() {
            let v = rec.value(name).ok_or(Error::BadSettings)?;
            if !setting(name).is_some_and(|s| s.accepts(f64::from(v))) {
                return Err(Error::BadSettings);
            }
            if let Some(slot) = p.slot(name) {
                *slot = c(f64::from(v));
            }
        }
        let get = |n| {
            rec.value(n)
                .map(|v| c(f64::from(v)))
                .ok_or(Error::BadSettings)
        };
        let limits = [get("u_min")?, get("u_max")?, get("slew")?];
        let sensor = [get("guard")?, get("stuck")?];
        self.install_settings(p, limits, sensor)
            .map_err(|_| Error::BadSettings)
    }

    /// The built-in settings (`defaults`): those of a fresh [`Loop`].
    pub fn default_settings(&mut self) -> Result<(), Error> {
        let l = converter_config::<C>(self.sample_hz).axes[0].limits;
        self.install_settings(
            Params::default(),
            [l.volts_min, l.volts_max, l.slew_volts_per_s],
            [c(default_of("guard")), c(default_of("stuck"))],
        )
    }

    /// Installs the parameters, the limits `[u_min, u_max, slew]` (V, V, V/s) and the
    /// sensor checks `[guard, stuck]` (um, samples), with the checks of `set`, all or none.
    fn install_settings(
        &mut self,
        p: Params,
        [lo, hi, slew]: [R; 3],
        [guard, stuck]: [R; 2],
    ) -> Result<(), Error> {
        if !(lo >= c(0.0) && lo < hi && hi <= c(150.0) && slew > c(0.0)) {
            return Err(Error::OutOfRange);
        }
        let whole = stuck.to_f64();
        let sensor_ok = [("guard", guard.to_f64()), ("stuck", whole)]
            .iter()
            .all(|(n, v)| setting(n).is_some_and(|s| s.accepts(*v)));
        if !(sensor_ok && whole == (whole as u32) as f64) {
            return Err(Error::OutOfRange);
        }
        let lp = self;
        let old = lp.params;
        lp.install(p)?;
        let limits = lp.set_limits(|l| {
            l.volts_min = lo;
            l.volts_max = hi;
            l.slew_volts_per_s = slew;
        });
        if let Err(e) = limits {
            // Keep the old settings whole rather than a mix.
            let _ = lp.install(old);
            return Err(e);
        }
        // Checked above; the window of a guard within its range always validates.
        lp.set_guard(guard)?;
        lp.stuck_limit = whole as u32;
        Ok(())
    }

    /// `load`: the stored record, checked and installed whole.
    pub fn load_settings<F: NorFlash>(
        &mut self,
        flash: &mut SettingsFlash<F>,
    ) -> Result<(), Error> {
        let mut buf = [0u8; MAX_RECORD];
        let n = flash.load(&mut buf)?.ok_or(Error::NoSettings)?;
        let rec = decode(buf.get(..n).ok_or(Error::BadSettings)?)?;
        self.apply_settings(&rec)
    }

    /// `save`: the current settings into `flash` (refused while the loop drives the stage).
    pub fn save_settings<F: NorFlash>(&self, flash: &mut SettingsFlash<F>) -> Result<usize, Error> {
        let mut buf = [0u8; MAX_RECORD];
        let n = self.settings_record(&mut buf)?;
        flash.save(buf.get(..n).ok_or(Error::Flash)?)?;
        Ok(n)
    }

    /// At power-up: the stored settings if a valid record is there, else the defaults. No
    /// erase ([`SettingsFlash::boot_load`]).
    pub fn boot_settings<F: NorFlash>(&mut self, flash: &mut SettingsFlash<F>) -> Boot {
        let mut buf = [0u8; MAX_RECORD];
        let got = flash.boot_load(&mut buf);
        Boot::of(
            flash,
            got.and_then(|n| n.ok_or(Error::NoSettings))
                .and_then(|n| decode(buf.get(..n).ok_or(Error::BadSettings)?))
                .and_then(|rec| self.apply_settings(&rec)),
        )
    }
}
