//! LZ4-frame chunk decompression for MCAP, in pure Rust (`lz4_flex`), so that olmap needs
//! no C lz4 library. The reader hands compressed bytes over in pieces; whole frames are
//! collected (their length is known from the frame's block headers), decoded at once and
//! handed back as the reader asks.

use mcap::sans_io::decompressor::{DecompressResult, Decompressor};
use mcap::{McapError, McapResult};

const FRAME_MAGIC: u32 = 0x184D_2204;

/// The `"lz4"` chunk decompressor registered with olmap's MCAP readers.
#[derive(Debug, Default)]
pub struct Lz4FrameDecoder {
    pending: Vec<u8>,
    out: Vec<u8>,
    out_pos: usize,
}

/// The length of the (skippable or LZ4) frame at the start of `buf`, `Ok(None)` while the
/// frame is incomplete.
fn frame_len(buf: &[u8]) -> Result<Option<usize>, String> {
    let u32_at = |i: usize| -> Option<u32> {
        buf.get(i..i + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let Some(magic) = u32_at(0) else {
        return Ok(None);
    };
    if magic & 0xFFFF_FFF0 == 0x184D_2A50 {
        return Ok(u32_at(4)
            .map(|n| 8 + n as usize)
            .filter(|&n| n <= buf.len()));
    }
    if magic != FRAME_MAGIC {
        return Err(format!("not an LZ4 frame (magic {magic:#010x})"));
    }
    let Some(&flg) = buf.get(4) else {
        return Ok(None);
    };
    let block_checksum = flg & 0x10 != 0;
    let content_size = flg & 0x08 != 0;
    let content_checksum = flg & 0x04 != 0;
    let dict_id = flg & 0x01 != 0;
    let mut pos = 4 + 2 + 1 + if content_size { 8 } else { 0 } + if dict_id { 4 } else { 0 };
    loop {
        let Some(size) = u32_at(pos) else {
            return Ok(None);
        };
        pos += 4;
        if size == 0 {
            pos += if content_checksum { 4 } else { 0 };
            return Ok((pos <= buf.len()).then_some(pos));
        }
        pos += (size & 0x7FFF_FFFF) as usize + if block_checksum { 4 } else { 0 };
        if pos > buf.len() {
            return Ok(None);
        }
    }
}

impl Lz4FrameDecoder {
    /// A decoder ready for its first chunk.
    pub fn new() -> Self {
        Self::default()
    }

    fn decode_complete_frames(&mut self) -> McapResult<()> {
        while let Some(n) = frame_len(&self.pending).map_err(McapError::DecompressionError)? {
            let frame: Vec<u8> = self.pending.drain(..n).collect();
            if u32::from_le_bytes([frame[0], frame[1], frame[2], frame[3]]) == FRAME_MAGIC {
                let mut decoder = lz4_flex::frame::FrameDecoder::new(&frame[..]);
                std::io::Read::read_to_end(&mut decoder, &mut self.out)
                    .map_err(|e| McapError::DecompressionError(format!("lz4: {e}")))?;
            }
        }
        Ok(())
    }
}

impl Decompressor for Lz4FrameDecoder {
    fn next_read_size(&self) -> usize {
        0
    }

    fn decompress(&mut self, src: &[u8], dst: &mut [u8]) -> McapResult<DecompressResult> {
        let mut consumed = 0;
        if self.out_pos == self.out.len() {
            self.out.clear();
            self.out_pos = 0;
            self.pending.extend_from_slice(src);
            consumed = src.len();
            self.decode_complete_frames()?;
        }
        let n = dst.len().min(self.out.len() - self.out_pos);
        dst[..n].copy_from_slice(&self.out[self.out_pos..self.out_pos + n]);
        self.out_pos += n;
        Ok(DecompressResult { consumed, wrote: n })
    }

    fn reset(&mut self) -> McapResult<()> {
        self.pending.clear();
        self.out.clear();
        self.out_pos = 0;
        Ok(())
    }

    fn name(&self) -> &'static str {
        "lz4"
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn frames_fed_in_pieces_come_back_whole() {
        let data: Vec<u8> = (0..200_000u32).map(|i| (i * 7 % 251) as u8).collect();
        let mut compressed = Vec::new();
        for part in [&data[..120_000], &data[120_000..]] {
            let mut enc = lz4_flex::frame::FrameEncoder::new(Vec::new());
            enc.write_all(part).unwrap();
            compressed.extend(enc.finish().unwrap());
        }
        let mut d = Lz4FrameDecoder::new();
        let mut out = Vec::new();
        let mut src = &compressed[..];
        let mut dst = [0u8; 999];
        while out.len() < data.len() {
            let take = src.len().min(1000);
            let r = d.decompress(&src[..take], &mut dst).unwrap();
            src = &src[r.consumed..];
            out.extend_from_slice(&dst[..r.wrote]);
            assert!(r.consumed > 0 || r.wrote > 0 || take == 0, "no progress");
        }
        assert_eq!(out, data);
        assert!(frame_len(b"junkjunk").is_err());
    }
}
