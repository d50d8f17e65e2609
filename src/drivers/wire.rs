//! What a chip sees of an embedded-hal SPI transaction. The chip models (hal-sim's mocks
//! and the QEMU board's chips) read MOSI and answer on MISO through these, so both claim
//! the same thing about the bus: a `Read` clocks out words embedded-hal leaves to the bus
//! (the H743 adapter sends zeros) and a `Transfer` pads a short write the same way.

use embedded_hal::spi::Operation;

/// The MOSI level a transaction leaves behind (SDI idles at the last bit sent; `before`
/// when the transaction clocks nothing).
pub fn last_mosi_high(ops: &[Operation<'_, u8>], before: bool) -> bool {
    let mut high = before;
    for op in ops {
        high = match op {
            Operation::Write(w) => w.last().map_or(high, |b| b & 1 != 0),
            Operation::Transfer(r, w) if r.len() > w.len() => false,
            Operation::Transfer(_, w) => w.last().map_or(high, |b| b & 1 != 0),
            Operation::TransferInPlace(b) => b.last().map_or(high, |b| b & 1 != 0),
            Operation::Read([]) => high,
            Operation::Read(_) => false,
            Operation::DelayNs(_) => high,
        };
    }
    high
}

/// The first `N` MOSI bytes of a transaction (`0xFF` past its end) and how many of them
/// were clocked.
pub fn mosi_head<const N: usize>(ops: &[Operation<'_, u8>]) -> ([u8; N], usize) {
    let mut head = [0xFF; N];
    let mut n = 0;
    for op in ops {
        let (bytes, zeros): (&[u8], usize) = match op {
            Operation::Write(w) => (w, 0),
            Operation::Transfer(r, w) => (w, r.len().saturating_sub(w.len())),
            Operation::TransferInPlace(b) => (b, 0),
            Operation::Read(r) => (&[], r.len()),
            Operation::DelayNs(_) => (&[], 0),
        };
        for b in bytes.iter().copied().chain(core::iter::repeat_n(0, zeros)) {
            if let Some(h) = head.get_mut(n) {
                *h = b;
                n += 1;
            }
        }
    }
    (head, n)
}

/// Answers a transaction: the read buffers take `miso` in clock order (zeros past its
/// end), a delay goes to `delay` (ns). Returns the bytes clocked.
pub fn clock_miso(ops: &mut [Operation<'_, u8>], miso: &[u8], mut delay: impl FnMut(u32)) -> usize {
    let mut k = 0;
    for op in ops.iter_mut() {
        match op {
            Operation::Read(r) | Operation::TransferInPlace(r) => {
                for b in r.iter_mut() {
                    *b = miso.get(k).copied().unwrap_or(0);
                    k += 1;
                }
            }
            Operation::Transfer(r, w) => {
                for b in r.iter_mut() {
                    *b = miso.get(k).copied().unwrap_or(0);
                    k += 1;
                }
                k += w.len().saturating_sub(r.len());
            }
            Operation::Write(w) => k += w.len(),
            Operation::DelayNs(ns) => delay(*ns),
        }
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn head_counts_read_words_as_zeros() {
        let w = [0x54u8];
        let mut r = [0u8; 2];
        let ops = [Operation::Write(&w), Operation::Read(&mut r)];
        assert_eq!(mosi_head::<2>(&ops), ([0x54, 0], 2));
        assert!(!last_mosi_high(&ops, true));
        let ops: [Operation<'_, u8>; 1] = [Operation::DelayNs(5)];
        assert_eq!(mosi_head::<2>(&ops), ([0xFF, 0xFF], 0));
        assert!(last_mosi_high(&ops, true));
    }

    #[test]
    fn miso_in_clock_order_then_zeros() {
        let (mut a, mut b) = ([9u8; 2], [9u8; 3]);
        let w = [1u8];
        let mut slept = 0;
        let mut ops = [
            Operation::Read(&mut a),
            Operation::DelayNs(7),
            Operation::Write(&w),
            Operation::TransferInPlace(&mut b),
        ];
        assert_eq!(clock_miso(&mut ops, &[1, 2, 3, 4], |ns| slept += ns), 6);
        assert_eq!((a, b, slept), ([1, 2], [4, 0, 0], 7));
    }
}
