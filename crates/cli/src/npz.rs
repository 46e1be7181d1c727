//! NumPy `.npz` archives (a zip of `.npy` files, stored or deflated, as `np.savez` and
//! `np.savez_compressed` write them), over the `zip` crate with only its deflate support.
//! npyz's own `npz` feature pulls zip 0.6 with every compressor it knows; zstd's C build
//! alone cost 42 s of a cold release build (docs/performance.md, "Build time").

use npyz::{AutoSerialize, NpyFile, WriterBuilder};
use std::fs::File;
use std::io::{self, BufReader, BufWriter, Cursor, Read, Write};
use std::path::Path;
use zip::result::ZipError;
use zip::write::SimpleFileOptions;

/// Largest `.npy` entry read (decompressed): a bound against zip bombs, far above any case.
const MAX_ENTRY_BYTES: u64 = 1 << 31;

fn io_err(e: ZipError) -> io::Error {
    match e {
        ZipError::Io(e) => e,
        other => io::Error::new(io::ErrorKind::InvalidData, other),
    }
}

/// An `.npz` opened for reading.
pub struct NpzReader {
    zip: zip::ZipArchive<BufReader<File>>,
}

impl NpzReader {
    pub fn open(path: &Path) -> io::Result<Self> {
        let zip = zip::ZipArchive::new(BufReader::new(File::open(path)?)).map_err(io_err)?;
        Ok(NpzReader { zip })
    }

    /// The array `name` (entry `name.npy`), or `None` when the archive has no such entry.
    pub fn by_name(&mut self, name: &str) -> io::Result<Option<NpyFile<Cursor<Vec<u8>>>>> {
        let mut entry = match self.zip.by_name(&format!("{name}.npy")) {
            Ok(e) => e,
            Err(ZipError::FileNotFound) => return Ok(None),
            Err(e) => return Err(io_err(e)),
        };
        let mut bytes = Vec::new();
        (&mut entry).take(MAX_ENTRY_BYTES).read_to_end(&mut bytes)?;
        NpyFile::new(Cursor::new(bytes)).map(Some)
    }
}

/// An `.npz` being written (entries stored, as `np.savez` does).
pub struct NpzWriter {
    zip: zip::ZipWriter<BufWriter<File>>,
}

impl NpzWriter {
    pub fn create(path: &Path) -> io::Result<Self> {
        let zip = zip::ZipWriter::new(BufWriter::new(File::create(path)?));
        Ok(NpzWriter { zip })
    }

    /// Adds the array `name` of `shape` (C order) holding `data`.
    pub fn put<T: AutoSerialize>(
        &mut self,
        name: &str,
        shape: &[usize],
        data: impl IntoIterator<Item = T>,
    ) -> io::Result<()> {
        let shape: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
        let mut buf = Vec::new();
        let mut w = npyz::WriteOptions::new()
            .default_dtype()
            .shape(&shape)
            .writer(&mut buf)
            .begin_nd()?;
        w.extend(data)?;
        w.finish()?;
        let opts = SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored)
            .large_file(buf.len() as u64 >= u32::MAX as u64);
        self.zip
            .start_file(format!("{name}.npy"), opts)
            .map_err(io_err)?;
        self.zip.write_all(&buf)
    }

    /// Writes the central directory and flushes the file.
    pub fn finish(self) -> io::Result<()> {
        self.zip.finish().map_err(io_err)?.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrays_round_trip_with_shape_and_dtype() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.npz");
        let mut w = NpzWriter::create(&path).unwrap();
        w.put("x", &[2, 3], [1.0f64, 2.0, 3.0, 4.0, 5.0, -6.5])
            .unwrap();
        w.put("n", &[], [7i64]).unwrap();
        w.put("r", &[2, 2], [1i32, -2, 3, 4]).unwrap();
        w.finish().unwrap();
        let mut r = NpzReader::open(&path).unwrap();
        let x = r.by_name("x").unwrap().unwrap();
        assert_eq!(x.shape(), &[2, 3]);
        assert_eq!(
            x.into_vec::<f64>().unwrap(),
            [1.0, 2.0, 3.0, 4.0, 5.0, -6.5]
        );
        let n = r.by_name("n").unwrap().unwrap();
        assert!(n.shape().is_empty());
        assert_eq!(n.into_vec::<i64>().unwrap(), [7]);
        let rr = r.by_name("r").unwrap().unwrap();
        assert_eq!(rr.into_vec::<i32>().unwrap(), [1, -2, 3, 4]);
        assert!(r.by_name("missing").unwrap().is_none());
    }

    #[test]
    fn a_file_that_is_not_a_zip_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.npz");
        std::fs::write(&path, b"not a zip at all").unwrap();
        assert!(NpzReader::open(&path).is_err());
    }
}
