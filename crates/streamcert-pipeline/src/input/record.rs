//! [`RecordReader`]: CSV records with the csv crate's grammar (its `csv-core` state machine,
//! default dialect: quotes `"` doubled inside quoted fields, `\n`, `\r` and `\r\n` end a
//! record, blank lines skipped), read from one reused buffer.
//!
//! Most rows of a sensor log are plain: no quote and no carriage return inside the line.
//! Those are split at the delimiter with `memchr` (SIMD) and their fields are slices of the
//! buffer; every other record goes through `csv_core::Reader`, so quoted fields, line breaks
//! inside quotes and lone carriage returns read exactly as the csv crate reads them (tested
//! field by field against `csv::Reader` on random inputs). The line of a record is the
//! physical line its first byte is on (the csv crate reports the line where its read began,
//! which for `\r\n` files is the previous line).

use std::io::{self, Read};

/// Bytes asked of the source per read.
const CHUNK: usize = 1 << 16;

/// Where the current record's fields are.
#[derive(Clone, Copy)]
enum Held {
    /// Fields separated by one delimiter byte from `buf[start]` on.
    Plain { start: usize },
    /// Fields concatenated in `fields`, ends in `ends` (csv-core's output).
    Parsed,
}

/// A streaming CSV record reader (see the module documentation).
pub(crate) struct RecordReader<R> {
    src: R,
    buf: Vec<u8>,
    /// Unconsumed bytes are `buf[pos..end]`.
    pos: usize,
    end: usize,
    eof: bool,
    /// Physical line of `buf[pos]`, 1-based.
    at_line: u64,
    delimiter: u8,
    /// Boxed: its transition tables are most of its size.
    core: Box<csv_core::Reader>,
    /// Field ends: offsets after each field's last byte (relative to the record's start for
    /// a plain line, the delimiter's offset; into `fields` for a parsed record).
    ends: Vec<usize>,
    fields: Vec<u8>,
    held: Held,
    record_line: u64,
}

impl<R: Read> RecordReader<R> {
    /// A reader of `src` with field delimiter `delimiter`.
    pub(crate) fn new(src: R, delimiter: u8) -> Self {
        Self {
            src,
            buf: vec![0; CHUNK],
            pos: 0,
            end: 0,
            eof: false,
            at_line: 1,
            delimiter,
            core: Box::new(csv_core::ReaderBuilder::new().delimiter(delimiter).build()),
            ends: Vec::with_capacity(64),
            fields: Vec::new(),
            held: Held::Parsed,
            record_line: 1,
        }
    }

    /// The physical line the current record starts on.
    pub(crate) fn line(&self) -> u64 {
        self.record_line
    }

    /// The line the reader is at (for an I/O error between records).
    pub(crate) fn position_line(&self) -> u64 {
        self.at_line
    }

    /// Number of fields of the current record.
    pub(crate) fn len(&self) -> usize {
        self.ends.len()
    }

    /// Field `i` of the current record.
    pub(crate) fn get(&self, i: usize) -> Option<&[u8]> {
        let end = *self.ends.get(i)?;
        Some(match self.held {
            Held::Plain { start } => {
                let from = if i == 0 { 0 } else { self.ends[i - 1] + 1 };
                &self.buf[start + from..start + end]
            }
            Held::Parsed => {
                let from = if i == 0 { 0 } else { self.ends[i - 1] };
                &self.fields[from..end]
            }
        })
    }

    /// Move the unconsumed bytes to the front and read more; `false` at the end of input.
    fn fill(&mut self) -> io::Result<bool> {
        if self.eof {
            return Ok(false);
        }
        self.buf.copy_within(self.pos..self.end, 0);
        self.end -= self.pos;
        self.pos = 0;
        if self.buf.len() - self.end < CHUNK {
            self.buf.resize(self.end + CHUNK, 0);
        }
        let n = loop {
            match self.src.read(&mut self.buf[self.end..]) {
                Ok(n) => break n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        };
        self.end += n;
        if n == 0 {
            self.eof = true;
        }
        Ok(n > 0)
    }

    /// Read the next record; `false` at the end of input.
    ///
    /// A line is taken as soon as its `\n` has arrived, so a live feed is answered row by
    /// row (a plain last line without `\n` is taken at the end of input).
    ///
    /// # Errors
    /// The source's read errors.
    pub(crate) fn read_record(&mut self) -> io::Result<bool> {
        loop {
            // Blank lines and lone terminators before a record are skipped (as csv-core
            // does at the start of a record).
            while self.pos < self.end && matches!(self.buf[self.pos], b'\n' | b'\r') {
                self.at_line += u64::from(self.buf[self.pos] == b'\n');
                self.pos += 1;
            }
            if self.pos == self.end {
                if self.fill()? {
                    continue;
                }
                return Ok(false);
            }
            let rest = &self.buf[self.pos..self.end];
            let Some(nl) = memchr::memchr(b'\n', rest) else {
                if self.fill()? {
                    continue;
                }
                // The last line, without a terminator.
                return self.take(self.end - self.pos, false);
            };
            return self.take(nl, true);
        }
    }

    /// Take the record of the next `len` bytes (a whole line without its `\n`, which
    /// follows when `newline`), plain or through csv-core.
    fn take(&mut self, len: usize, newline: bool) -> io::Result<bool> {
        let start = self.pos;
        let mut line = &self.buf[start..start + len];
        if line.last() == Some(&b'\r') {
            line = &line[..len - 1];
        }
        if memchr::memchr2(b'"', b'\r', line).is_none() {
            self.ends.clear();
            for at in memchr::memchr_iter(self.delimiter, line) {
                self.ends.push(at);
            }
            self.ends.push(line.len());
            self.held = Held::Plain { start };
            self.record_line = self.at_line;
            self.pos = start + len + usize::from(newline);
            self.at_line += u64::from(newline);
            return Ok(true);
        }
        self.parse_with_core()
    }

    /// The next record through csv-core (quotes, carriage returns): a record, since at
    /// least one byte that is not a terminator is ahead.
    fn parse_with_core(&mut self) -> io::Result<bool> {
        use csv_core::ReadRecordResult as Res;
        self.core.reset();
        self.record_line = self.at_line;
        self.held = Held::Parsed;
        self.ends.clear();
        self.ends.resize(16, 0);
        if self.fields.is_empty() {
            self.fields.resize(256, 0);
        }
        let (mut nout, mut nend) = (0, 0);
        loop {
            // An empty input tells csv-core the input ended; it then returns the record.
            let input = &self.buf[self.pos..self.end];
            let (res, nin, o, e) =
                self.core.read_record(input, &mut self.fields[nout..], &mut self.ends[nend..]);
            self.at_line += memchr::memchr_iter(b'\n', &input[..nin]).count() as u64;
            self.pos += nin;
            nout += o;
            nend += e;
            match res {
                // More of a quoted field is ahead: read on (at the end of input the next
                // call passes the empty slice).
                Res::InputEmpty => {
                    self.fill()?;
                }
                Res::OutputFull => {
                    let n = self.fields.len();
                    self.fields.resize(2 * n, 0);
                }
                Res::OutputEndsFull => {
                    let n = self.ends.len();
                    self.ends.resize(2 * n, 0);
                }
                Res::Record => {
                    self.ends.truncate(nend);
                    return Ok(true);
                }
                Res::End => return Ok(false),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A source that hands out at most `sizes[k]` bytes at its `k`-th read (cycling), as a
    /// pipe does.
    struct Trickle<'a> {
        data: &'a [u8],
        sizes: Vec<usize>,
        k: usize,
    }

    impl Read for Trickle<'_> {
        fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
            let n = self.sizes[self.k % self.sizes.len()].min(out.len()).min(self.data.len());
            self.k += 1;
            out[..n].copy_from_slice(&self.data[..n]);
            self.data = &self.data[n..];
            Ok(n)
        }
    }

    type Records = Vec<(u64, Vec<Vec<u8>>)>;

    fn ours(data: &[u8], delimiter: u8, sizes: Vec<usize>) -> Records {
        let mut r = RecordReader::new(Trickle { data, sizes, k: 0 }, delimiter);
        let mut out = Vec::new();
        while r.read_record().expect("in memory") {
            let fields = (0..r.len()).map(|i| r.get(i).expect("field").to_vec()).collect();
            out.push((r.line(), fields));
        }
        out
    }

    fn csv_crate(data: &[u8], delimiter: u8) -> Vec<Vec<Vec<u8>>> {
        let mut r = csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .delimiter(delimiter)
            .from_reader(data);
        let mut rec = csv::ByteRecord::new();
        let mut out = Vec::new();
        while r.read_byte_record(&mut rec).expect("in memory") {
            out.push(rec.iter().map(<[u8]>::to_vec).collect());
        }
        out
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        /// The csv crate is the oracle: the same records, field by field, for any bytes of
        /// the alphabet that matters (delimiters, quotes, line ends) and any read sizes.
        #[test]
        fn reads_what_the_csv_crate_reads(
            text in proptest::collection::vec(
                prop_oneof![Just(b'a'), Just(b'1'), Just(b','), Just(b';'), Just(b'"'),
                            Just(b'\r'), Just(b'\n'), Just(b' ')], 0..120),
            semicolon in any::<bool>(),
            sizes in proptest::collection::vec(1usize..9, 1..4),
        ) {
            let delimiter = if semicolon { b';' } else { b',' };
            let got: Vec<_> = ours(&text, delimiter, sizes).into_iter().map(|r| r.1).collect();
            prop_assert_eq!(got, csv_crate(&text, delimiter));
        }

        /// Line numbers never decrease and never pass the input's last line.
        #[test]
        fn line_numbers_are_physical(
            text in proptest::collection::vec(
                prop_oneof![Just(b'a'), Just(b','), Just(b'"'), Just(b'\r'), Just(b'\n')], 0..80),
        ) {
            let lines = 1 + text.iter().filter(|&&b| b == b'\n').count() as u64;
            let got = ours(&text, b',', vec![3]);
            for w in got.windows(2) {
                prop_assert!(w[0].0 <= w[1].0);
            }
            for (line, _) in &got {
                prop_assert!(*line >= 1 && *line <= lines);
            }
        }
    }

    #[test]
    fn a_record_is_on_the_line_its_first_byte_is_on() {
        let lines = |text: &str| -> Vec<u64> {
            ours(text.as_bytes(), b',', vec![2, 64]).into_iter().map(|r| r.0).collect()
        };
        assert_eq!(lines("h\n1\n2\n"), [1, 2, 3]);
        // The csv crate says 1, 1, 2 here (the line where its read began).
        assert_eq!(lines("h\r\n1\r\n2\r\n"), [1, 2, 3]);
        assert_eq!(lines("h\n\n1\n\n\n2"), [1, 3, 6]);
        assert_eq!(lines("h\n1,\"a\nb\"\n2\n"), [1, 2, 4]);
        assert_eq!(lines("h\r\n\r\n1\r\n"), [1, 3]);
    }

    #[test]
    fn long_lines_and_quoted_fields_cross_the_buffer() {
        let long = "x".repeat(3 * CHUNK);
        let text = format!("a,{long}\n\"{long}\n,\"\"\",b\nc\n");
        let got = ours(text.as_bytes(), b',', vec![CHUNK / 3, 7]);
        let fields: Vec<_> = got.iter().map(|r| r.1.clone()).collect();
        assert_eq!(fields, csv_crate(text.as_bytes(), b','));
        assert_eq!(got.iter().map(|r| r.0).collect::<Vec<_>>(), [1, 2, 4]);
    }
}
