//! 16-bit PNGs written and read for the tests, and ffmpeg's `lut3d` filter applied to
//! them: the independent reader of the project's 3D LUTs.

use std::path::Path;

use super::succeed;

pub fn write_png16(path: &Path, width: u32, pixels: &[[u16; 3]]) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut encoder = png::Encoder::new(file, width, pixels.len() as u32 / width);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Sixteen);
    let mut writer = encoder.write_header().unwrap();
    let bytes: Vec<u8> = pixels
        .iter()
        .flat_map(|p| p.iter().flat_map(|v| v.to_be_bytes()))
        .collect();
    writer.write_image_data(&bytes).unwrap();
}

pub fn read_png16(path: &Path) -> Vec<[u16; 3]> {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buffer = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buffer).unwrap();
    assert_eq!(
        (info.color_type, info.bit_depth),
        (png::ColorType::Rgb, png::BitDepth::Sixteen)
    );
    buffer[..info.buffer_size()]
        .chunks(6)
        .map(|p| [0, 1, 2].map(|c| u16::from_be_bytes([p[2 * c], p[2 * c + 1]])))
        .collect()
}

/// ffmpeg's lut3d filter (tetrahedral) applied to `input`, 16 bits in and out.
pub fn ffmpeg_lut3d(input: &Path, lut: &Path, output: &Path) -> Vec<[u16; 3]> {
    super::need_tool("ffmpeg", "ffmpeg");
    succeed(
        std::process::Command::new("ffmpeg")
            .args(["-y", "-loglevel", "error", "-i"])
            .arg(input)
            .arg("-vf")
            .arg(format!("lut3d=file={}:interp=tetrahedral", lut.display()))
            .args(["-pix_fmt", "rgb48be"])
            .arg(output),
    );
    read_png16(output)
}
