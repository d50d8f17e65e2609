//! CMSDK APB UART0 of the mps2 machines (0x4000_4000, QEMU `-serial`): the receiver
//! interrupts (UARTRX0, the mps2's external interrupt 0), the transmitter is polled.

const BASE: usize = 0x4000_4000;
const DATA: usize = BASE;
const STATE: usize = BASE + 0x4;
const CTRL: usize = BASE + 0x8;
const INTCLEAR: usize = BASE + 0xC;
const BAUDDIV: usize = BASE + 0x10;
/// CTRL: transmitter, receiver and receive interrupt enabled.
const CTRL_TX_RX_RXINT: u32 = 0b1011;
/// INTSTATUS / INTCLEAR: the receive interrupt.
const INT_RX: u32 = 2;
const TX_FULL: u32 = 1;
const RX_FULL: u32 = 2;

#[allow(unsafe_code)]
fn read(addr: usize) -> u32 {
    // SAFETY: a CMSDK UART register of the mps2 memory map, always mapped.
    unsafe { core::ptr::read_volatile(addr as *const u32) }
}
#[allow(unsafe_code)]
fn write(addr: usize, v: u32) {
    // SAFETY: as above; only the UART owns these addresses.
    unsafe { core::ptr::write_volatile(addr as *mut u32, v) }
}

/// 115200 Bd at 25 MHz, transmitter and receiver on, the receive interrupt on.
pub fn init() {
    write(BAUDDIV, 217);
    write(CTRL, CTRL_TX_RX_RXINT);
}

/// Clears the receive interrupt (before reading: a byte that arrives after sets it again).
pub fn clear_rx_interrupt() {
    write(INTCLEAR, INT_RX);
}

pub fn try_read() -> Option<u8> {
    if read(STATE) & RX_FULL != 0 {
        Some(read(DATA) as u8)
    } else {
        None
    }
}

pub fn write_bytes(bytes: &[u8]) {
    for &b in bytes {
        // Bounded wait: QEMU drains the holding register at once.
        for _ in 0..100_000 {
            if read(STATE) & TX_FULL == 0 {
                break;
            }
        }
        write(DATA, b as u32);
    }
}

pub fn line(s: &str) {
    write_bytes(s.as_bytes());
    write_bytes(b"\n");
}
