//! LZF decompression (Marc Lehmann's liblzf format), for PCD `binary_compressed`
//! bodies as PCL and Open3D write them.
//!
//! The stream is a sequence of chunks, each starting with a control byte `c`:
//!
//! - `c < 32`: a literal run, the next `c + 1` bytes copied as they are;
//! - otherwise a back reference: length `(c >> 5) + 2`, where a length field of 7 means
//!   "7 plus the next byte", followed by the low byte of the offset; the copy starts
//!   `((c & 31) << 8 | low) + 1` bytes back in the output and may overlap what it writes.

use super::FormatError;

/// The most output one input byte can produce: a 3-byte back reference copies up to
/// 264 bytes.
const MAX_EXPANSION: usize = 88;

/// Decompress `input`, which must expand to exactly `expected` bytes.
///
/// Never writes past `expected` bytes nor allocates more than `input` could expand to.
///
/// # Errors
///
/// [`FormatError::Lzf`] for a chunk running past the end of the input, a back
/// reference before the start of the output, output beyond `expected`, or output
/// ending short of it.
pub(super) fn decompress(input: &[u8], expected: usize) -> Result<Vec<u8>, FormatError> {
    let capacity = expected.min(input.len().saturating_mul(MAX_EXPANSION));
    let mut out = Vec::with_capacity(capacity);
    let mut bytes = input.iter().copied().enumerate();
    let cut = |at: usize| FormatError::Lzf(format!("chunk at compressed byte {at} is cut short"));
    let overflow = |at: usize| {
        FormatError::Lzf(format!(
            "chunk at compressed byte {at} expands beyond the declared {expected} bytes"
        ))
    };
    while let Some((at, control)) = bytes.next() {
        let control = usize::from(control);
        if control < 32 {
            let len = control + 1;
            let literal = input.get(at + 1..at + 1 + len).ok_or_else(|| cut(at))?;
            if out.len() + len > expected {
                return Err(overflow(at));
            }
            out.extend_from_slice(literal);
            // Skip the literal bytes just copied.
            bytes.nth(len - 1);
        } else {
            let mut len = control >> 5;
            if len == 7 {
                len += usize::from(bytes.next().ok_or_else(|| cut(at))?.1);
            }
            let low = usize::from(bytes.next().ok_or_else(|| cut(at))?.1);
            let back = ((control & 0x1f) << 8 | low) + 1;
            len += 2;
            if back > out.len() {
                return Err(FormatError::Lzf(format!(
                    "chunk at compressed byte {at} refers {back} bytes back, \
                     before the start of the data ({} bytes so far)",
                    out.len()
                )));
            }
            if out.len() + len > expected {
                return Err(overflow(at));
            }
            let start = out.len() - back;
            for i in start..start + len {
                let byte = out[i];
                out.push(byte);
            }
        }
    }
    if out.len() != expected {
        return Err(FormatError::Lzf(format!(
            "data expands to {} bytes, {expected} declared",
            out.len()
        )));
    }
    Ok(out)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// A simple valid LZF encoder for tests: greedy matches against the previous
    /// 8 KiB, literal runs of at most 32 bytes.
    pub(in super::super) fn compress(data: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut literal: Vec<u8> = Vec::new();
        let flush = |out: &mut Vec<u8>, literal: &mut Vec<u8>| {
            for chunk in literal.chunks(32) {
                out.push((chunk.len() - 1) as u8);
                out.extend_from_slice(chunk);
            }
            literal.clear();
        };
        let mut i = 0;
        while i < data.len() {
            let mut best = (0, 0);
            for back in 1..=i.min(2048) {
                let mut len = 0;
                while i + len < data.len() && len < 264 && data[i - back + len] == data[i + len] {
                    len += 1;
                }
                if len > best.0 {
                    best = (len, back);
                }
            }
            let (len, back) = best;
            if len >= 3 {
                flush(&mut out, &mut literal);
                let off = back - 1;
                let l = len - 2;
                if l < 7 {
                    out.push(((l << 5) | (off >> 8)) as u8);
                } else {
                    out.push(((7 << 5) | (off >> 8)) as u8);
                    out.push((l - 7) as u8);
                }
                out.push((off & 0xff) as u8);
                i += len;
            } else {
                literal.push(data[i]);
                i += 1;
            }
        }
        flush(&mut out, &mut literal);
        out
    }

    #[test]
    fn literals_and_overlapping_back_references() {
        // "abc" literal, then a 7-byte copy from 3 back (overlapping), then a long run.
        let input = [2, b'a', b'b', b'c', (5 << 5), 2, (7 << 5), 10, 0];
        let out = decompress(&input, 3 + 7 + 19).unwrap();
        assert_eq!(&out[..10], b"abcabcabca");
        assert!(out[10..].iter().all(|&b| b == b'a'));
    }

    #[test]
    fn encoder_round_trips() {
        let data: Vec<u8> = (0..5000u32)
            .map(|i| ((i * 7) % 13 + (i / 300)) as u8)
            .collect();
        let packed = compress(&data);
        assert!(packed.len() < data.len() / 2);
        assert_eq!(decompress(&packed, data.len()).unwrap(), data);
        assert_eq!(decompress(&compress(b"xyz"), 3).unwrap(), b"xyz");
        assert_eq!(decompress(&[], 0).unwrap(), b"");
    }

    #[test]
    fn bad_streams_are_errors() {
        let err = |input: &[u8], n| decompress(input, n).unwrap_err().to_string();
        assert_eq!(
            err(&[3, b'a', b'b'], 4),
            "bad binary_compressed body: chunk at compressed byte 0 is cut short"
        );
        assert_eq!(
            err(&[0, b'a', 1 << 5, 5], 10),
            "bad binary_compressed body: chunk at compressed byte 2 refers 6 bytes back, \
             before the start of the data (1 bytes so far)"
        );
        assert_eq!(
            err(&[0, b'a', 1 << 5, 0], 3),
            "bad binary_compressed body: chunk at compressed byte 2 expands beyond \
             the declared 3 bytes"
        );
        assert_eq!(
            err(&[1, b'a', b'b'], 3),
            "bad binary_compressed body: data expands to 2 bytes, 3 declared"
        );
        assert!(decompress(&[0, b'a', 7 << 5], 100).is_err());
        assert!(decompress(&[0, b'a', 7 << 5, 1], 100).is_err());
        // A huge declared size is not allocated up front.
        assert!(decompress(&[0, b'a'], usize::MAX).is_err());
    }
}
