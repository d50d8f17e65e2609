//! The recorder's binary bulk transfer (`rec bin <start> <count>`): frames go out in
//! packets, each COBS-framed (no zero byte inside, a zero byte after it) and checked by a
//! CRC-32, so a damaged packet is found and asked for again instead of read as data.
//!
//! A packet before framing: `start` (u32 LE, index of its first frame), `count` (u8, 1 ..=
//! [`FRAMES_PER_PACKET`]), `channels` (u8), [`FORMAT`] (u16 LE: f32 LE values), the values
//! frame by frame (`count * channels` f32 LE), CRC-32 (ISO-HDLC, u32 LE) of all before it.
//! [`encode`] frames one, [`decode`] checks and unpacks one (without its zero delimiter).
//!
//! The COBS coder is this module's own, not the `cobs` crate's: that encoder panics when its
//! output is too small (slice indexing), and the command handler must have no panic path
//! (the firmware safety check); this one returns `None` instead and is bounded by its input.
//! Both directions are proptested and `decode` is fuzzed (`hal-sim/fuzz`, `rec_packet`).

use crc::{Crc, CRC_32_ISO_HDLC};

/// Frames per packet.
pub const FRAMES_PER_PACKET: usize = 32;
/// Channels a packet can carry.
pub const MAX_CHANNELS: usize = 4;
/// Values layout: 1 = f32 little endian.
pub const FORMAT: u16 = 1;
const HEADER: usize = 8;
const CRC_LEN: usize = 4;
/// Longest packet before framing.
pub const MAX_PAYLOAD: usize = HEADER + FRAMES_PER_PACKET * MAX_CHANNELS * 4 + CRC_LEN;
/// Longest framed packet, its zero delimiter included (COBS adds one byte per 254).
pub const MAX_FRAMED: usize = MAX_PAYLOAD + MAX_PAYLOAD.div_ceil(254) + 1;

const CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// Why a packet was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PacketError {
    /// Not valid COBS (a zero byte inside, a code running past the end), or too long.
    Framing,
    /// Shorter than a header and checksum, or its length does not match its header.
    Length,
    /// The CRC-32 does not match: damaged on the way.
    Checksum,
    /// Unknown values format, no frames, too many frames or channels.
    Header,
}

/// A checked packet: `count` frames of `channels` values from frame `start` on.
#[derive(Debug, Clone, PartialEq)]
pub struct Packet {
    pub start: u32,
    pub count: usize,
    pub channels: usize,
    values: [f32; FRAMES_PER_PACKET * MAX_CHANNELS],
}

impl Packet {
    /// Frame `k` of the packet (`k < count`).
    pub fn frame(&self, k: usize) -> Option<&[f32]> {
        if k >= self.count {
            return None;
        }
        self.values.get(k * self.channels..(k + 1) * self.channels)
    }
}

/// COBS-encodes `src` into `out` followed by the zero delimiter; the bytes written, or
/// `None` when `out` is too small. No panic; one pass over `src`.
pub fn cobs_encode(src: &[u8], out: &mut [u8]) -> Option<usize> {
    let mut code_at = 0usize;
    let mut w = 1usize;
    let mut code = 1u8;
    for &b in src {
        if b == 0 {
            *out.get_mut(code_at)? = code;
            code_at = w;
            w += 1;
            code = 1;
        } else {
            *out.get_mut(w)? = b;
            w += 1;
            code += 1;
            if code == 0xFF {
                *out.get_mut(code_at)? = code;
                code_at = w;
                w += 1;
                code = 1;
            }
        }
    }
    *out.get_mut(code_at)? = code;
    *out.get_mut(w)? = 0;
    Some(w + 1)
}

/// COBS-decodes `src` (without the delimiter) into `out`; the bytes written, or `None` for
/// a zero byte inside, a block running past the end, or `out` too small.
pub fn cobs_decode(src: &[u8], out: &mut [u8]) -> Option<usize> {
    let (mut r, mut w) = (0usize, 0usize);
    while r < src.len() {
        let code = *src.get(r)?;
        if code == 0 {
            return None;
        }
        r += 1;
        for _ in 1..code {
            let b = *src.get(r)?;
            if b == 0 {
                return None;
            }
            *out.get_mut(w)? = b;
            w += 1;
            r += 1;
        }
        if code != 0xFF && r < src.len() {
            *out.get_mut(w)? = 0;
            w += 1;
        }
    }
    Some(w)
}

/// Frames `frames` (channel values per frame, at most [`FRAMES_PER_PACKET`] frames of at
/// most [`MAX_CHANNELS`]), the first being frame `start`, into `out` as one COBS packet with
/// its delimiter; the bytes written (`None`: nothing to send or `out` too small).
pub fn encode<const CH: usize>(start: u32, frames: &[[f32; CH]], out: &mut [u8]) -> Option<usize> {
    if frames.is_empty() || frames.len() > FRAMES_PER_PACKET || CH == 0 || CH > MAX_CHANNELS {
        return None;
    }
    let mut p = [0u8; MAX_PAYLOAD];
    let [s0, s1, s2, s3] = start.to_le_bytes();
    let [f0, f1] = FORMAT.to_le_bytes();
    let head = [s0, s1, s2, s3, frames.len() as u8, CH as u8, f0, f1];
    let mut n = 0;
    for b in head
        .into_iter()
        .chain(frames.iter().flatten().flat_map(|v| v.to_le_bytes()))
    {
        *p.get_mut(n)? = b;
        n += 1;
    }
    let crc = CRC32.checksum(p.get(..n)?);
    for b in crc.to_le_bytes() {
        *p.get_mut(n)? = b;
        n += 1;
    }
    cobs_encode(p.get(..n)?, out)
}

/// Checks and unpacks one framed packet (`framed` without its zero delimiter).
pub fn decode(framed: &[u8]) -> Result<Packet, PacketError> {
    let mut p = [0u8; MAX_PAYLOAD];
    let n = cobs_decode(framed, &mut p).ok_or(PacketError::Framing)?;
    let p = p.get(..n).ok_or(PacketError::Framing)?;
    if n < HEADER + CRC_LEN {
        return Err(PacketError::Length);
    }
    let (body, crc) = p.split_at(n - CRC_LEN);
    let crc = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if CRC32.checksum(body) != crc {
        return Err(PacketError::Checksum);
    }
    let (head, values) = body.split_at(HEADER);
    let start = u32::from_le_bytes([head[0], head[1], head[2], head[3]]);
    let (count, channels) = (head[4] as usize, head[5] as usize);
    if u16::from_le_bytes([head[6], head[7]]) != FORMAT
        || count == 0
        || count > FRAMES_PER_PACKET
        || channels == 0
        || channels > MAX_CHANNELS
    {
        return Err(PacketError::Header);
    }
    if values.len() != count * channels * 4 {
        return Err(PacketError::Length);
    }
    let mut out = Packet {
        start,
        count,
        channels,
        values: [0.0; FRAMES_PER_PACKET * MAX_CHANNELS],
    };
    for (v, b) in out.values.iter_mut().zip(values.chunks_exact(4)) {
        *v = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn framed(start: u32, frames: &[[f32; 4]]) -> Vec<u8> {
        let mut out = [0u8; MAX_FRAMED];
        let n = encode(start, frames, &mut out).unwrap();
        out[..n].to_vec()
    }

    #[test]
    fn cobs_known_vectors() {
        // From the COBS paper / Wikipedia's examples.
        let cases: [(&[u8], &[u8]); 4] = [
            (&[0x00], &[0x01, 0x01, 0x00]),
            (&[0x00, 0x00], &[0x01, 0x01, 0x01, 0x00]),
            (
                &[0x11, 0x22, 0x00, 0x33],
                &[0x03, 0x11, 0x22, 0x02, 0x33, 0x00],
            ),
            (
                &[0x11, 0x00, 0x00, 0x00],
                &[0x02, 0x11, 0x01, 0x01, 0x01, 0x00],
            ),
        ];
        for (src, want) in cases {
            let mut out = [0u8; 16];
            let n = cobs_encode(src, &mut out).unwrap();
            assert_eq!(&out[..n], want);
            let mut back = [0u8; 16];
            let m = cobs_decode(&want[..want.len() - 1], &mut back).unwrap();
            assert_eq!(&back[..m], src);
        }
        // 254 non-zero bytes: one full block, then the delimiter's block.
        let src: Vec<u8> = (1..=254).collect();
        let mut out = [0u8; 300];
        let n = cobs_encode(&src, &mut out).unwrap();
        assert_eq!((n, out[0], out[255], out[256]), (257, 0xFF, 0x01, 0x00));
        assert!(cobs_encode(&src, &mut out[..256]).is_none());
    }

    #[test]
    fn a_packet_round_trips_and_its_size_is_bounded() {
        let frames: Vec<[f32; 4]> = (0..32).map(|k| [k as f32, -1.5, 0.0, f32::MAX]).collect();
        let f = framed(1_000_000, &frames);
        assert!(f.len() <= MAX_FRAMED);
        assert_eq!(f.iter().position(|&b| b == 0), Some(f.len() - 1));
        let p = decode(&f[..f.len() - 1]).unwrap();
        assert_eq!((p.start, p.count, p.channels), (1_000_000, 32, 4));
        for (k, fr) in frames.iter().enumerate() {
            assert_eq!(p.frame(k).unwrap(), fr);
        }
        assert!(p.frame(32).is_none());
        let mut out = [0u8; MAX_FRAMED];
        assert!(encode::<4>(0, &[], &mut out).is_none());
        assert!(encode(0, &frames[..1], &mut out[..10]).is_none());
        let two: Vec<[f32; 2]> = vec![[1.0, 2.0]; 3];
        let n = encode(7, &two, &mut out).unwrap();
        let p = decode(&out[..n - 1]).unwrap();
        assert_eq!(
            (p.start, p.count, p.channels, p.frame(2)),
            (7, 3, 2, Some(&[1.0f32, 2.0][..]))
        );
    }

    #[test]
    fn truncated_or_empty_packets_are_refused() {
        let f = framed(5, &[[1.0, 2.0, 3.0, 4.0]; 3]);
        let body = &f[..f.len() - 1];
        assert!(decode(&[]).is_err());
        for cut in 1..body.len() {
            assert!(decode(&body[..cut]).is_err(), "cut at {cut}");
        }
    }

    proptest! {
        /// COBS: the framed bytes hold no zero but the delimiter and decode to the input.
        #[test]
        fn cobs_round_trips(src in proptest::collection::vec(any::<u8>(), 0..700)) {
            let mut out = vec![0u8; src.len() + src.len() / 254 + 2];
            let n = cobs_encode(&src, &mut out).unwrap();
            prop_assert_eq!(out[..n - 1].iter().filter(|&&b| b == 0).count(), 0);
            prop_assert_eq!(out[n - 1], 0);
            let mut back = vec![0u8; src.len()];
            let m = cobs_decode(&out[..n - 1], &mut back).unwrap();
            prop_assert_eq!(&back[..m], &src[..]);
        }

        /// Any 1 to 3 flipped bits in the packet's bytes (the CRC-32's guaranteed
        /// detection: Hamming distance 4 at these lengths) are refused.
        #[test]
        fn flipped_bits_in_a_packet_are_refused(
            start in any::<u32>(),
            values in proptest::collection::vec(any::<f32>(), 4..=128),
            flips in proptest::collection::btree_set(any::<usize>(), 1..=3),
        ) {
            let frames: Vec<[f32; 4]> = values.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
            let f = framed(start, &frames);
            // Damage the packet before framing, then frame it again (a damaged payload
            // that reached the decoder with its framing intact).
            let mut p = [0u8; MAX_PAYLOAD];
            let n = cobs_decode(&f[..f.len() - 1], &mut p).unwrap();
            let bits = n * 8;
            let mut seen = std::collections::BTreeSet::new();
            for b in flips {
                let b = b % bits;
                if seen.insert(b) {
                    p[b / 8] ^= 1 << (b % 8);
                } else {
                    prop_assume!(false);
                }
            }
            let mut again = [0u8; MAX_FRAMED];
            let m = cobs_encode(&p[..n], &mut again).unwrap();
            prop_assert!(decode(&again[..m - 1]).is_err());
        }

        /// Any change of the framed bytes on the wire (1 to 4 bytes replaced by other
        /// values, zeros included: a split packet) is refused.
        #[test]
        fn damaged_framed_bytes_are_refused(
            values in proptest::collection::vec(-1e3f32..1e3, 4..=128),
            hits in proptest::collection::vec((any::<usize>(), 1u8..=255), 1..=4),
        ) {
            let frames: Vec<[f32; 4]> = values.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
            let f = framed(3, &frames);
            let mut body = f[..f.len() - 1].to_vec();
            let mut seen = std::collections::BTreeSet::new();
            for (at, x) in hits {
                let at = at % body.len();
                // Distinct bytes: two hits on one byte could cancel out.
                prop_assume!(seen.insert(at));
                body[at] ^= x;
            }
            // A zero splits the packet on the wire: each part is decoded on its own.
            for part in body.split(|&b| b == 0) {
                prop_assert!(decode(part).is_err());
            }
        }

        /// Arbitrary bytes never panic the decoder.
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..1200)) {
            let _ = decode(&bytes);
        }
    }
}
