//! PNG files for people to look at (frames, flow, contact sheets, plots),
//! written with the `png` crate.

use std::path::Path;

/// Why an image could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PngError {
    /// The pixel buffer does not match the size and channel count.
    #[error("{width}×{height} image with {channels} channels needs {need} bytes, got {got}")]
    Size {
        /// Width, px.
        width: u32,
        /// Height, px.
        height: u32,
        /// Channels.
        channels: u8,
        /// Bytes needed.
        need: usize,
        /// Bytes given.
        got: usize,
    },
    /// Only grey (1) and RGB (3) are written.
    #[error("{0} channels: only 1 (grey) or 3 (RGB) are written")]
    Channels(u8),
    /// The file could not be created or written.
    #[error("{}: {source}", path.display())]
    File {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: png::EncodingError,
    },
}

/// Writes an 8-bit image with `channels` 1 (grey) or 3 (RGB), row-major,
/// to `path`.
pub fn write(
    path: impl AsRef<Path>,
    width: u32,
    height: u32,
    channels: u8,
    pixels: &[u8],
) -> Result<(), PngError> {
    let color = match channels {
        1 => png::ColorType::Grayscale,
        3 => png::ColorType::Rgb,
        c => return Err(PngError::Channels(c)),
    };
    let need = width as usize * height as usize * channels as usize;
    if pixels.len() != need {
        return Err(PngError::Size {
            width,
            height,
            channels,
            need,
            got: pixels.len(),
        });
    }
    let path = path.as_ref();
    let file_err = |source| PngError::File {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::File::create(path).map_err(|e| file_err(e.into()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    enc.set_color(color);
    enc.set_depth(png::BitDepth::Eight);
    let mut w = enc.write_header().map_err(file_err)?;
    w.write_image_data(pixels).map_err(file_err)?;
    w.finish().map_err(file_err)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_images_decode_to_the_same_pixels() {
        let dir = test_support::scratch_dir("png");
        for (channels, name) in [(1u8, "grey.png"), (3, "rgb.png")] {
            let (w, h) = (5u32, 3u32);
            let px: Vec<u8> = (0..w * h * channels as u32)
                .map(|i| (i * 37 % 251) as u8)
                .collect();
            let path = dir.join(name);
            write(&path, w, h, channels, &px).unwrap();
            let dec =
                png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()));
            let mut r = dec.read_info().unwrap();
            let mut buf = vec![0; r.output_buffer_size().unwrap()];
            let info = r.next_frame(&mut buf).unwrap();
            assert_eq!((info.width, info.height), (w, h));
            assert_eq!(&buf[..info.buffer_size()], &px[..], "{name}");
        }
        assert!(matches!(
            write(dir.join("bad.png"), 2, 2, 3, &[0; 5]),
            Err(PngError::Size { need: 12, .. })
        ));
        assert!(matches!(
            write(dir.join("bad.png"), 1, 1, 2, &[0; 2]),
            Err(PngError::Channels(2))
        ));
    }
}
