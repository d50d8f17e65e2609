//! The recorder's bulk-transfer packet decoder (issue 17 items 2 and 8): `bulk::decode` on
//! arbitrary bytes never panics; a packet it accepts is self-consistent (frames and
//! channels in range) and framed again decodes to the same packet, bit for bit; and the
//! fuzzer's bytes as frame values round-trip.
#![no_main]
use libfuzzer_sys::fuzz_target;
use piezo_core::bulk::{decode, encode, FRAMES_PER_PACKET, MAX_CHANNELS, MAX_FRAMED};

fuzz_target!(|data: &[u8]| {
    if let Ok(p) = decode(data) {
        assert!((1..=FRAMES_PER_PACKET).contains(&p.count));
        assert!((1..=MAX_CHANNELS).contains(&p.channels));
        if p.channels == MAX_CHANNELS {
            let frames: Vec<[f32; MAX_CHANNELS]> = (0..p.count)
                .map(|k| {
                    let f = p.frame(k).unwrap();
                    [f[0], f[1], f[2], f[3]]
                })
                .collect();
            let mut out = [0u8; MAX_FRAMED];
            let n = encode(p.start, &frames, &mut out).unwrap();
            let q = decode(&out[..n - 1]).unwrap();
            assert_eq!((q.start, q.count, q.channels), (p.start, p.count, p.channels));
            for k in 0..p.count {
                let (a, b) = (p.frame(k).unwrap(), q.frame(k).unwrap());
                assert!(a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()));
            }
        }
    }
    // The same bytes as the values of a packet: framed, they decode to themselves.
    let values: Vec<f32> = data
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .take(FRAMES_PER_PACKET * MAX_CHANNELS)
        .collect();
    let frames: Vec<[f32; MAX_CHANNELS]> = values
        .chunks_exact(MAX_CHANNELS)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    if !frames.is_empty() {
        let mut out = [0u8; MAX_FRAMED];
        let n = encode(7, &frames, &mut out).unwrap();
        let p = decode(&out[..n - 1]).unwrap();
        assert_eq!((p.start, p.count), (7, frames.len()));
        for (k, f) in frames.iter().enumerate() {
            let got = p.frame(k).unwrap();
            assert!(got.iter().zip(f).all(|(a, b)| a.to_bits() == b.to_bits()));
        }
    }
});
