//! A bounded walk over Parquet's Thrift-encoded footer and page headers,
//! run before the parquet crate reads them.
//!
//! The crate skips fields it does not know by following the declared
//! sizes, and counts a boolean list element as taking no bytes: a 6 KB file
//! whose page header declared lists of 2³¹ booleans kept it busy for
//! seconds per header (found by fuzzing). This walk follows the same rules
//! but counts its steps, so such a file is refused in time proportional to
//! its size. Valid headers take one step per field and a few bytes each.

/// Why a walk stopped.
#[derive(Debug, PartialEq)]
pub(crate) enum Refusal {
    /// The encoding ran past its bytes or used an undefined type.
    Malformed,
    /// More steps than the bytes can justify.
    TooMuchWork,
}

/// Thrift compact-protocol types, as in the field and list headers.
const BOOL_TRUE: u8 = 1;
const BOOL_FALSE: u8 = 2;
const I32: u8 = 5;
const MAX_DEPTH: u8 = 64;

pub(crate) struct Walk<'a> {
    buf: &'a [u8],
    pub(crate) pos: usize,
    budget: u64,
}

impl<'a> Walk<'a> {
    /// A walk over `buf` allowed `budget` steps in all.
    pub(crate) fn new(buf: &'a [u8], budget: u64) -> Self {
        Walk { buf, pos: 0, budget }
    }

    /// Steps left; what a caller passes on to the next walk.
    pub(crate) fn budget(&self) -> u64 {
        self.budget
    }

    pub(crate) fn at(&mut self, pos: usize) {
        self.pos = pos;
    }

    fn step(&mut self) -> Result<(), Refusal> {
        self.budget = self.budget.checked_sub(1).ok_or(Refusal::TooMuchWork)?;
        Ok(())
    }

    fn byte(&mut self) -> Result<u8, Refusal> {
        let b = *self.buf.get(self.pos).ok_or(Refusal::Malformed)?;
        self.pos += 1;
        Ok(b)
    }

    fn skip_bytes(&mut self, n: u64) -> Result<(), Refusal> {
        let end = usize::try_from(n)
            .ok()
            .and_then(|n| self.pos.checked_add(n))
            .filter(|&e| e <= self.buf.len())
            .ok_or(Refusal::Malformed)?;
        self.pos = end;
        Ok(())
    }

    fn varint(&mut self) -> Result<u64, Refusal> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.byte()?;
            v |= u64::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(Refusal::Malformed)
    }

    fn zigzag(&mut self) -> Result<i64, Refusal> {
        let v = self.varint()?;
        Ok((v >> 1) as i64 ^ -((v & 1) as i64))
    }

    /// One value of type `ty`, skipped as the parquet crate skips it.
    fn skip(&mut self, ty: u8, depth: u8) -> Result<(), Refusal> {
        self.step()?;
        let depth = depth.checked_sub(1).ok_or(Refusal::Malformed)?;
        match ty {
            BOOL_TRUE | BOOL_FALSE => Ok(()),
            3 => self.byte().map(drop),
            4..=6 => self.varint().map(drop),
            7 => self.skip_bytes(8),
            8 => {
                let n = self.varint()?;
                self.skip_bytes(n)
            }
            9 | 10 => {
                let header = self.byte()?;
                if header == 0 {
                    return Ok(());
                }
                let n = match header >> 4 {
                    15 => self.varint()?,
                    n => u64::from(n),
                };
                if n > i32::MAX as u64 {
                    return Err(Refusal::Malformed);
                }
                for _ in 0..n {
                    self.skip(header & 0x0f, depth)?;
                }
                Ok(())
            }
            11 => {
                let n = self.varint()?;
                if n > 0 {
                    let kv = self.byte()?;
                    for _ in 0..n {
                        self.skip(kv >> 4, depth)?;
                        self.skip(kv & 0x0f, depth)?;
                    }
                }
                Ok(())
            }
            12 => self.fields(depth, |_, _, _| Ok(false)),
            13 => self.skip_bytes(16),
            _ => Err(Refusal::Malformed),
        }
    }

    /// A struct's fields up to its stop byte. `take(walk, id, type)` may
    /// read a field itself (returning true); the others are skipped.
    fn fields(
        &mut self,
        depth: u8,
        mut take: impl FnMut(&mut Self, i16, u8) -> Result<bool, Refusal>,
    ) -> Result<(), Refusal> {
        let mut last = 0i16;
        loop {
            self.step()?;
            let header = self.byte()?;
            let ty = header & 0x0f;
            if ty == 0 {
                return Ok(());
            }
            let id = match header >> 4 {
                0 => i16::try_from(self.zigzag()?).map_err(|_| Refusal::Malformed)?,
                delta => last.checked_add(i16::from(delta)).ok_or(Refusal::Malformed)?,
            };
            last = id;
            if !take(self, id, ty)? {
                self.skip(ty, depth)?;
            }
        }
    }

    /// A whole struct (the file's metadata).
    pub(crate) fn structure(&mut self) -> Result<(), Refusal> {
        self.skip(12, MAX_DEPTH)
    }

    /// A page header; returns its `compressed_page_size` (field 3).
    pub(crate) fn page_header(&mut self) -> Result<i64, Refusal> {
        let mut size = None;
        self.fields(MAX_DEPTH, |w, id, ty| {
            if id == 3 && ty == I32 {
                size = Some(w.zigzag()?);
                return Ok(true);
            }
            Ok(false)
        })?;
        size.ok_or(Refusal::Malformed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_valid_header_is_read() {
        // type=DATA_PAGE(0) i32, uncompressed 100, compressed 60, then a
        // data_page_header struct {num_values: 10}, stop.
        let buf = [0x15, 0x00, 0x15, 0xc8, 0x01, 0x15, 0x78, 0x2c, 0x15, 0x14, 0x00, 0x00];
        let mut w = Walk::new(&buf, 100);
        assert_eq!(w.page_header(), Ok(60));
        assert_eq!(w.pos, buf.len());
    }

    #[test]
    fn a_list_of_two_billion_booleans_is_too_much_work() {
        // Field 9 (delta 9) a list (type 9) of 2³¹−1 booleans: 7 bytes.
        let buf = [0x99, 0xf1, 0xff, 0xff, 0xff, 0xff, 0x07, 0x00];
        let mut w = Walk::new(&buf, 1000);
        let t = std::time::Instant::now();
        assert_eq!(w.page_header(), Err(Refusal::TooMuchWork));
        assert!(t.elapsed().as_secs_f64() < 0.1);
    }

    #[test]
    fn a_length_past_the_end_is_malformed() {
        let buf = [0x18, 0xff, 0x01, 0x00];
        assert_eq!(Walk::new(&buf, 100).page_header(), Err(Refusal::Malformed));
    }
}
