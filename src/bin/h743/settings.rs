//! The settings flash: the last two 128 KiB sectors of flash bank 2 (sectors 6 and 7,
//! 0x081C_0000..0x0820_0000), through the HAL's bank. The code runs from bank 1 only
//! (build.rs gives the linker bank 1's 1 MiB as FLASH), so programming bank 2 never stalls
//! an instruction fetch (RM0433 4.3.11: one bank is read while the other is written), and
//! the control interrupt runs from ITCM anyway. Used from init (boot) and idle only
//! ([`piezo_core::firmware::run_flash_job`]).

use cortex_m::peripheral::SCB;
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use piezo_core::firmware::SettingsFlash;
use stm32h7xx_hal::flash::{Error, LockedFlashBank};

/// Offsets of the settings sectors within bank 2.
pub const SECTORS: core::ops::Range<u32> = 0xC_0000..0x10_0000;
/// The D-cache line (Cortex-M7).
const LINE: usize = 32;

/// Bank 2, unlocked only for the length of one erase or program, with the D-cache lines
/// of what changed invalidated afterwards: flash is cacheable (write-through) and the
/// controller changes it behind the cache, so a read after an erase could otherwise return
/// the old bytes (PM0253 4.8, cache maintenance).
pub struct SettingsBank {
    bank: LockedFlashBank,
    scb: SCB,
}

impl SettingsBank {
    fn invalidate(&mut self, offset: u32, len: usize) {
        let start = (self.bank.address() + offset as usize) & !(LINE - 1);
        let end = self.bank.address() + offset as usize + len;
        // SAFETY: line-aligned, whole lines of flash: memory the CPU never writes through
        // the cache, so nothing is lost; the next read fetches what the flash holds.
        #[allow(unsafe_code)]
        unsafe {
            self.scb
                .invalidate_dcache_by_address(start, (end - start).next_multiple_of(LINE))
        };
    }
}

impl ErrorType for SettingsBank {
    type Error = Error;
}

impl ReadNorFlash for SettingsBank {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Error> {
        self.bank.read(offset, bytes)
    }
    fn capacity(&self) -> usize {
        self.bank.len()
    }
}

impl NorFlash for SettingsBank {
    const WRITE_SIZE: usize = 32;
    const ERASE_SIZE: usize = 0x2_0000;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), Error> {
        let r = self.bank.unlocked().erase(from, to);
        self.invalidate(from, to.saturating_sub(from) as usize);
        r
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Error> {
        let r = self.bank.unlocked().write(offset, bytes);
        self.invalidate(offset, bytes.len());
        r
    }
}

/// Set in RAM that survives a reset (`.uninit`, not zeroed at boot) while init reads the
/// settings flash. A power loss while a flash word was programmed can leave an ECC double
/// error there, and a read of that word is a bus error: the HardFault's safe state, then
/// the watchdog's reset. Found set at the next boot, the read is not tried again: the
/// defaults run and idle erases the sectors (what they hold cannot be read), instead of a
/// fault at every boot.
const READING: u32 = 0x5E77_1265;
#[allow(unsafe_code)]
#[unsafe(link_section = ".uninit.settings_read")]
static mut READ_MARK: core::mem::MaybeUninit<u32> = core::mem::MaybeUninit::uninit();

/// Marks the start (`true`) or end of init's settings read; returns whether the mark was
/// set before (the previous boot faulted during the read).
pub fn mark_read(on: bool) -> bool {
    // SAFETY: init alone touches it (interrupts off); any bit pattern is a valid u32, so
    // reading RAM the reset left uninitialised is defined.
    #[allow(unsafe_code)]
    unsafe {
        let p = core::ptr::addr_of_mut!(READ_MARK).cast::<u32>();
        let was = p.read_volatile() == READING;
        p.write_volatile(if on { READING } else { 0 });
        was
    }
}

/// The settings flash over bank 2's settings sectors (`None`: a part without bank 2, or a
/// geometry `sequential-storage` refuses: `save`/`load` then answer err 13).
pub fn settings_flash(
    bank2: Option<LockedFlashBank>,
    scb: SCB,
) -> Option<SettingsFlash<SettingsBank>> {
    let bank = bank2?;
    SettingsFlash::new(SettingsBank { bank, scb }, SECTORS).ok()
}
