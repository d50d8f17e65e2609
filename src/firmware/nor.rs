//! A RAM-backed NOR flash as strict as the H743's (the QEMU board's settings flash and the
//! host tests'), and the adapter from a blocking flash to the async traits
//! `sequential-storage` is written against.
//!
//! The rules of the real part, enforced: erase only whole sectors (`ERASE` bytes, erased
//! state 0xFF); program only whole, aligned flash words (`WRITE` bytes; the H743 programs
//! 256-bit words) and only a word that is still erased (no write without erase: the H743's
//! ECC forbids programming a word twice). A power loss can be injected after any number of
//! changed bytes ([`RamNor::cut_after`]): the operation under way stops at that byte and
//! every later one fails until [`RamNor::power_on`].

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// What the flash refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NorError {
    /// Offset or length not a multiple of the erase or write granularity.
    NotAligned,
    /// Outside the flash.
    OutOfBounds,
    /// Programming a word that is not erased.
    NotErased,
    /// The power went away during or before this operation.
    PowerLost,
}

impl NorFlashError for NorError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            NorError::NotAligned => NorFlashErrorKind::NotAligned,
            NorError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            NorError::NotErased | NorError::PowerLost => NorFlashErrorKind::Other,
        }
    }
}

/// `SIZE` bytes of NOR flash in RAM, erased in sectors of `ERASE` bytes, programmed in
/// words of `WRITE` bytes.
#[derive(Clone)]
pub struct RamNor<const SIZE: usize, const ERASE: usize, const WRITE: usize> {
    bytes: [u8; SIZE],
    /// Bytes that may still change before the power goes (`None`: no cut planned).
    budget: Option<usize>,
    powered: bool,
    /// Bytes changed (programmed or erased) since start (the cut points of a test).
    pub changed: usize,
    /// Erases asked since start (an H743 sector erase takes seconds).
    pub erases: usize,
}

impl<const SIZE: usize, const ERASE: usize, const WRITE: usize> RamNor<SIZE, ERASE, WRITE> {
    /// A fully erased flash.
    pub const fn new() -> Self {
        Self {
            bytes: [0xFF; SIZE],
            budget: None,
            powered: true,
            changed: 0,
            erases: 0,
        }
    }

    /// The raw contents (tests and fuzzing corrupt them here).
    pub fn bytes_mut(&mut self) -> &mut [u8; SIZE] {
        &mut self.bytes
    }

    /// Plans a power loss after `bytes` more changed bytes (`None`: never).
    pub fn cut_after(&mut self, bytes: Option<usize>) {
        self.budget = bytes;
    }

    /// Power back on after a cut (the contents stay as the cut left them).
    pub fn power_on(&mut self) {
        self.powered = true;
        self.budget = None;
    }

    /// One byte change, unless the power is (now) gone.
    fn change(&mut self, at: usize, v: u8) -> Result<(), NorError> {
        if !self.powered {
            return Err(NorError::PowerLost);
        }
        if let Some(b) = self.budget.as_mut() {
            if *b == 0 {
                self.powered = false;
                return Err(NorError::PowerLost);
            }
            *b -= 1;
        }
        let byte = self.bytes.get_mut(at).ok_or(NorError::OutOfBounds)?;
        *byte = v;
        self.changed += 1;
        Ok(())
    }

    fn range(offset: u32, len: usize, align: usize) -> Result<core::ops::Range<usize>, NorError> {
        let start = offset as usize;
        let end = start.checked_add(len).ok_or(NorError::OutOfBounds)?;
        if end > SIZE {
            return Err(NorError::OutOfBounds);
        }
        if !start.is_multiple_of(align) || !len.is_multiple_of(align) {
            return Err(NorError::NotAligned);
        }
        Ok(start..end)
    }
}

impl<const SIZE: usize, const ERASE: usize, const WRITE: usize> Default
    for RamNor<SIZE, ERASE, WRITE>
{
    fn default() -> Self {
        Self::new()
    }
}

impl<const SIZE: usize, const ERASE: usize, const WRITE: usize> ErrorType
    for RamNor<SIZE, ERASE, WRITE>
{
    type Error = NorError;
}

impl<const SIZE: usize, const ERASE: usize, const WRITE: usize> ReadNorFlash
    for RamNor<SIZE, ERASE, WRITE>
{
    /// Whole words, like the H743, which reads its flash in 256-bit words (with ECC). This
    /// matters after a power loss: `sequential-storage` reads a page marker in `READ_SIZE`
    /// units, and a marker word cut half-written must read as written (it must not be
    /// programmed again).
    const READ_SIZE: usize = WRITE;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), NorError> {
        if !self.powered {
            return Err(NorError::PowerLost);
        }
        let r = Self::range(offset, bytes.len(), WRITE)?;
        bytes.copy_from_slice(self.bytes.get(r).ok_or(NorError::OutOfBounds)?);
        Ok(())
    }

    fn capacity(&self) -> usize {
        SIZE
    }
}

impl<const SIZE: usize, const ERASE: usize, const WRITE: usize> NorFlash
    for RamNor<SIZE, ERASE, WRITE>
{
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = ERASE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), NorError> {
        self.erases += 1;
        let len = (to as usize)
            .checked_sub(from as usize)
            .ok_or(NorError::OutOfBounds)?;
        let r = Self::range(from, len, ERASE)?;
        for at in r {
            self.change(at, 0xFF)?;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), NorError> {
        let r = Self::range(offset, bytes.len(), WRITE)?;
        let old = self.bytes.get(r.clone()).ok_or(NorError::OutOfBounds)?;
        // Every word written must be erased before (checked for all words first: a refused
        // write changes nothing).
        if old.iter().any(|b| *b != 0xFF) {
            return Err(NorError::NotErased);
        }
        for (at, v) in r.zip(bytes) {
            self.change(at, *v)?;
        }
        Ok(())
    }
}

/// A blocking flash seen through `embedded-storage-async`'s traits (each future is ready on
/// its first poll; see [`super::storage::block_on`]), whose erases can be refused: at boot,
/// where an H743 sector erase (2-4 s) would outlast the 100 ms boot watchdog, a repair that
/// needs one stops there, untouched, like a power loss just before it.
pub struct Blocking<F> {
    pub flash: F,
    /// Erases answer [`FlashError::EraseRefused`] (and change nothing).
    pub refuse_erase: bool,
    /// An erase was refused since this was last cleared.
    pub erase_refused: bool,
}

impl<F> Blocking<F> {
    pub const fn new(flash: F) -> Self {
        Self {
            flash,
            refuse_erase: false,
            erase_refused: false,
        }
    }
}

/// The flash's own error, or an erase [`Blocking`] refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlashError<E> {
    Flash(E),
    EraseRefused,
}

impl<E: NorFlashError> NorFlashError for FlashError<E> {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::Flash(e) => e.kind(),
            FlashError::EraseRefused => NorFlashErrorKind::Other,
        }
    }
}

impl<F: ErrorType> ErrorType for Blocking<F> {
    type Error = FlashError<F::Error>;
}

impl<F: ReadNorFlash> embedded_storage_async::nor_flash::ReadNorFlash for Blocking<F> {
    const READ_SIZE: usize = F::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.flash.read(offset, bytes).map_err(FlashError::Flash)
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<F: NorFlash> embedded_storage_async::nor_flash::NorFlash for Blocking<F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if self.refuse_erase {
            self.erase_refused = true;
            return Err(FlashError::EraseRefused);
        }
        self.flash.erase(from, to).map_err(FlashError::Flash)
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.flash.write(offset, bytes).map_err(FlashError::Flash)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type Nor = RamNor<1024, 256, 32>;

    #[test]
    fn the_rules_of_the_part() {
        let mut f = Nor::new();
        assert_eq!(f.write(0, &[0; 16]), Err(NorError::NotAligned));
        assert_eq!(f.write(16, &[0; 32]), Err(NorError::NotAligned));
        assert_eq!(f.write(1024, &[0; 32]), Err(NorError::OutOfBounds));
        assert_eq!(f.write(32, &[0x12; 32]), Ok(()));
        // No write without erase, even of the same data.
        assert_eq!(f.write(32, &[0x12; 32]), Err(NorError::NotErased));
        assert_eq!(f.erase(0, 128), Err(NorError::NotAligned));
        assert_eq!(f.erase(256, 0), Err(NorError::OutOfBounds));
        assert_eq!(f.erase(0, 256), Ok(()));
        let mut b = [0u8; 64];
        assert_eq!(f.read(7, &mut b), Err(NorError::NotAligned));
        f.read(32, &mut b).unwrap();
        assert!(b.iter().all(|b| *b == 0xFF));
        assert_eq!(f.write(32, &[0x34; 32]), Ok(()));
    }

    #[test]
    fn a_cut_stops_at_its_byte_and_everything_after_fails() {
        let mut f = Nor::new();
        f.cut_after(Some(5));
        assert_eq!(f.write(0, &[0; 32]), Err(NorError::PowerLost));
        assert_eq!(f.bytes_mut()[..6], [0, 0, 0, 0, 0, 0xFF]);
        let mut b = [0u8; 32];
        assert_eq!(f.read(0, &mut b), Err(NorError::PowerLost));
        f.power_on();
        assert_eq!(f.write(0, &[0; 32]), Err(NorError::NotErased));
        assert_eq!(f.erase(0, 256), Ok(()));
        assert_eq!(f.changed, 5 + 256);
    }
}
