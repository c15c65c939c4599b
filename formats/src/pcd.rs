//! PCD, the Point Cloud Library's format (v0.7): a text header (`VERSION FIELDS SIZE TYPE
//! COUNT WIDTH HEIGHT VIEWPOINT POINTS DATA`, `#` comments), then the points as `ascii` lines,
//! `binary` packed records (row-major) or `binary_compressed`: a u32 compressed size, a u32
//! uncompressed size, then LZF data that unpacks to all values of the first field, then all of
//! the second, and so on (column-major). Format as documented with PCL ("The PCD file format")
//! and written by PCL's `PCDWriter`.
//!
//! Entry points:
//! - [`parse`] (bytes) and [`read_pcd`] (a file) to a [`PcdCloud`], which keeps the organised
//!   grid: points in file order, invalid ones left as NaN, with labels and colours if present,
//!   and the sensor pose of the `VIEWPOINT` line.
//! - [`PcdCloud::into_cloud`] for the plain points (and normals).
//!
//! Fields are typed `F` (float, 4 or 8 bytes), `I` or `U` (signed or unsigned integers of 1, 2,
//! 4 or 8 bytes); fields with COUNT > 1 (feature histograms) and `_` padding are skipped.
//! Everything the header claims is checked against the data before any point is read.

use std::borrow::Cow;
use std::path::Path;

use glam::{Affine3A, Quat, Vec3};
use tacmesh_source::PointCloud;

use crate::FormatError;

/// A PCD cloud as stored: `width * height` points in file order (row-major over the grid when
/// `height > 1`), invalid points kept as NaN so the grid survives.
#[derive(Debug, Clone, PartialEq)]
pub struct PcdCloud {
    pub width: u32,
    pub height: u32,
    pub points: Vec<Vec3>,
    /// From `normal_x normal_y normal_z`, one per point.
    pub normals: Option<Vec<Vec3>>,
    /// From a `label` field (segmentation ground truth), one per point.
    pub labels: Option<Vec<u32>>,
    /// The raw bits of an `rgb` or `rgba` field (PCL packs them as 0xAARRGGBB), one per point.
    pub rgba: Option<Vec<u32>>,
    /// The sensor's pose in the cloud's frame, from `VIEWPOINT tx ty tz qw qx qy qz` (PCL's
    /// `sensor_origin_` and `sensor_orientation_`); `None` when the header has no such line.
    pub cloud_from_sensor: Option<Affine3A>,
}

impl PcdCloud {
    /// The points and normals, non-finite ones included (see [`PointCloud::retain_finite`]).
    pub fn into_cloud(self) -> PointCloud {
        match self.normals {
            Some(normals) => PointCloud::with_normals(self.points, normals),
            None => PointCloud::new(self.points),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Header

#[derive(Debug, Clone, Copy, PartialEq)]
enum DataKind {
    Ascii,
    Binary,
    BinaryCompressed,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Float,
    Signed,
    Unsigned,
}

#[derive(Debug)]
struct Field {
    name: String,
    kind: Kind,
    /// Bytes per element.
    size: usize,
    /// Elements per point.
    count: usize,
    /// Byte offset of the field within a packed record.
    offset: usize,
}

#[derive(Debug)]
struct Header {
    fields: Vec<Field>,
    width: u32,
    height: u32,
    points: usize,
    /// Bytes per packed point, the sum of size * count over the fields.
    record_size: usize,
    data: DataKind,
    /// Offset of the first byte after the DATA line.
    data_start: usize,
    /// Line number of the first line after the DATA line, for ascii data.
    data_line: usize,
    cloud_from_sensor: Option<Affine3A>,
}

impl Header {
    /// The field of that name, if any, checked to hold one value per point.
    fn field(&self, field: &str, name: &str) -> Result<Option<&Field>, FormatError> {
        match self.fields.iter().find(|f| f.name == field) {
            Some(f) if f.count != 1 => Err(FormatError::malformed(
                name,
                format!("field {field} has COUNT {}; expected 1", f.count),
            )),
            found => Ok(found),
        }
    }

    fn field_names(&self) -> String {
        let names: Vec<&str> = self.fields.iter().map(|f| f.name.as_str()).collect();
        names.join(" ")
    }
}

/// The header lines as written, before they are checked against each other.
#[derive(Default)]
struct HeaderLines {
    fields: Option<Vec<String>>,
    sizes: Option<Vec<usize>>,
    types: Option<Vec<char>>,
    counts: Option<Vec<usize>>,
    width: Option<u32>,
    height: Option<u32>,
    points: Option<u64>,
    viewpoint: Option<Affine3A>,
}

fn parse_header(bytes: &[u8], name: &str) -> Result<Header, FormatError> {
    let mut lines = HeaderLines::default();
    let mut start = 0;
    let mut line_number = 0;
    let (data, data_start, data_line) = loop {
        if start >= bytes.len() {
            return Err(FormatError::malformed(
                name,
                format!("the header ends after line {line_number} without a DATA line"),
            ));
        }
        line_number += 1;
        let end = bytes[start..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |i| start + i);
        let line = &bytes[start..end];
        start = (end + 1).min(bytes.len());
        let Ok(line) = std::str::from_utf8(line) else {
            return Err(FormatError::malformed(
                name,
                format!("header line {line_number} is not text"),
            ));
        };
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        if keyword.starts_with('#') {
            continue;
        }
        let values: Vec<&str> = words.collect();
        let bad = |what: &str| {
            FormatError::malformed(
                name,
                format!("header line {line_number} ({keyword}): {what}"),
            )
        };
        let numbers = || -> Result<Vec<usize>, FormatError> {
            values
                .iter()
                .map(|v| v.parse().map_err(|_| bad(&format!("{v:?} is not a count"))))
                .collect()
        };
        let single = || -> Result<u64, FormatError> {
            match values.as_slice() {
                [v] => v.parse().map_err(|_| bad(&format!("{v:?} is not a count"))),
                _ => Err(bad("expected one number")),
            }
        };
        let single_u32 = || -> Result<u32, FormatError> {
            u32::try_from(single()?).map_err(|_| bad("too large"))
        };
        match keyword {
            "VERSION" => {}
            "VIEWPOINT" => lines.viewpoint = Some(viewpoint(&values).map_err(|what| bad(&what))?),
            "FIELDS" | "COLUMNS" => {
                lines.fields = Some(values.iter().map(|v| v.to_string()).collect())
            }
            "SIZE" => lines.sizes = Some(numbers()?),
            "TYPE" => {
                let types = values.iter().map(|v| match *v {
                    "F" | "I" | "U" => Ok(v.chars().next().unwrap_or('?')),
                    other => Err(bad(&format!("type {other:?} is not F, I or U"))),
                });
                lines.types = Some(types.collect::<Result<_, _>>()?);
            }
            "COUNT" => lines.counts = Some(numbers()?),
            "WIDTH" => lines.width = Some(single_u32()?),
            "HEIGHT" => lines.height = Some(single_u32()?),
            "POINTS" => lines.points = Some(single()?),
            "DATA" => {
                let data = match values.as_slice() {
                    ["ascii"] => DataKind::Ascii,
                    ["binary"] => DataKind::Binary,
                    ["binary_compressed"] => DataKind::BinaryCompressed,
                    _ => return Err(bad("expected ascii, binary or binary_compressed")),
                };
                break (data, start, line_number + 1);
            }
            _ => return Err(bad("unknown keyword")),
        }
    };
    check_header(lines, data, (data_start, data_line), name)
}

/// Checks the header lines against each other and lays out the fields.
fn check_header(
    lines: HeaderLines,
    data: DataKind,
    (data_start, data_line): (usize, usize),
    name: &str,
) -> Result<Header, FormatError> {
    let bad = |what: String| FormatError::malformed(name, format!("header: {what}"));
    let fields = lines.fields.ok_or_else(|| bad("no FIELDS line".into()))?;
    let sizes = lines.sizes.ok_or_else(|| bad("no SIZE line".into()))?;
    let types = lines.types.ok_or_else(|| bad("no TYPE line".into()))?;
    let counts = lines.counts.unwrap_or_else(|| vec![1; fields.len()]);
    let width = lines.width.ok_or_else(|| bad("no WIDTH line".into()))?;
    let height = lines.height.ok_or_else(|| bad("no HEIGHT line".into()))?;
    if fields.is_empty() {
        return Err(bad("FIELDS is empty".into()));
    }
    for (line, len) in [
        ("SIZE", sizes.len()),
        ("TYPE", types.len()),
        ("COUNT", counts.len()),
    ] {
        if len != fields.len() {
            return Err(bad(format!(
                "{} FIELDS but {len} {line} entries",
                fields.len()
            )));
        }
    }
    let grid = u64::from(width) * u64::from(height);
    let points = lines.points.unwrap_or(grid);
    if points != grid {
        return Err(bad(format!(
            "POINTS is {points} but WIDTH * HEIGHT is {width} * {height} = {grid}"
        )));
    }
    let points =
        usize::try_from(points).map_err(|_| bad(format!("{points} points is too many")))?;

    let mut laid_out = Vec::with_capacity(fields.len());
    let mut offset = 0usize;
    for (((field, size), kind), count) in fields.into_iter().zip(sizes).zip(types).zip(counts) {
        let kind = match (kind, size) {
            ('F', 4 | 8) => Kind::Float,
            ('I', 1 | 2 | 4 | 8) => Kind::Signed,
            ('U', 1 | 2 | 4 | 8) => Kind::Unsigned,
            _ => {
                return Err(bad(format!(
                    "field {field} is TYPE {kind} with SIZE {size}"
                )))
            }
        };
        if count == 0 {
            return Err(bad(format!("field {field} has COUNT 0")));
        }
        let bytes = size
            .checked_mul(count)
            .ok_or_else(|| bad(format!("field {field} is too large")))?;
        laid_out.push(Field {
            name: field,
            kind,
            size,
            count,
            offset,
        });
        offset = offset
            .checked_add(bytes)
            .ok_or_else(|| bad("records are too large".into()))?;
    }
    if points.checked_mul(offset).is_none() {
        return Err(bad(format!(
            "{points} points of {offset} bytes is too many"
        )));
    }
    Ok(Header {
        fields: laid_out,
        width,
        height,
        points,
        record_size: offset,
        data,
        data_start,
        data_line,
        cloud_from_sensor: lines.viewpoint,
    })
}

/// The pose a VIEWPOINT line's seven numbers `tx ty tz qw qx qy qz` give; the quaternion need
/// not be normalised (PCL normalises it too), but must not be zero.
fn viewpoint(values: &[&str]) -> Result<Affine3A, String> {
    let numbers: Vec<f32> = values
        .iter()
        .map(|v| v.parse().map_err(|_| format!("{v:?} is not a number")))
        .collect::<Result<_, _>>()?;
    let [tx, ty, tz, qw, qx, qy, qz] = numbers[..] else {
        return Err(format!(
            "expected 7 numbers (tx ty tz qw qx qy qz), got {}",
            numbers.len()
        ));
    };
    let rotation = Quat::from_xyzw(qx, qy, qz, qw);
    let translation = Vec3::new(tx, ty, tz);
    if !(translation.is_finite() && rotation.is_finite() && rotation.length() > 1e-6) {
        return Err("the position must be finite and the quaternion finite and non-zero".into());
    }
    Ok(Affine3A::from_rotation_translation(
        rotation.normalize(),
        translation,
    ))
}

// ---------------------------------------------------------------------------------------------
// Data: everything is brought to packed little-endian records, row- or column-major.

#[derive(Debug, Clone, Copy, PartialEq)]
enum Layout {
    /// Point after point, each a packed record (ascii after conversion, binary).
    RowMajor,
    /// Field after field, each all points' values (binary_compressed after unpacking).
    ColumnMajor,
}

/// Converts ascii lines, one point each, to packed little-endian records.
fn ascii_records(data: &[u8], header: &Header, name: &str) -> Result<Vec<u8>, FormatError> {
    let n = header.points;
    // Every value needs at least two bytes of text ("0 ") and packs to at most 8, so the
    // records cannot outgrow four times the text, whatever COUNT and POINTS claim.
    let mut records = Vec::with_capacity((n * header.record_size).min(4 * data.len()));
    let mut read = 0;
    for (i, line) in data.split(|&b| b == b'\n').enumerate() {
        if read == n {
            break;
        }
        let line_number = header.data_line + i;
        let text = std::str::from_utf8(line)
            .map_err(|_| FormatError::malformed(name, format!("line {line_number} is not text")))?;
        if text.trim().is_empty() {
            continue;
        }
        let mut tokens = text.split_whitespace();
        for field in &header.fields {
            for _ in 0..field.count {
                let token = tokens.next().ok_or_else(|| {
                    FormatError::malformed(
                        name,
                        format!("line {line_number} ends before field {}", field.name),
                    )
                })?;
                encode_ascii(token, field, &mut records).ok_or_else(|| {
                    FormatError::malformed(
                        name,
                        format!(
                            "line {line_number}: {token:?} is not a valid {} (TYPE {} SIZE {})",
                            field.name,
                            kind_letter(field.kind),
                            field.size
                        ),
                    )
                })?;
            }
        }
        read += 1;
    }
    if read < n {
        return Err(FormatError::malformed(
            name,
            format!("header says {n} points but the ascii data has only {read}"),
        ));
    }
    Ok(records)
}

/// Appends one ascii value as `field.size` little-endian bytes; `None` if it does not parse
/// or does not fit.
fn encode_ascii(token: &str, field: &Field, out: &mut Vec<u8>) -> Option<()> {
    match (field.kind, field.size) {
        (Kind::Float, 4) => out.extend(token.parse::<f32>().ok()?.to_le_bytes()),
        (Kind::Float, _) => out.extend(token.parse::<f64>().ok()?.to_le_bytes()),
        (Kind::Unsigned, size) => {
            let v: u64 = token.parse().ok()?;
            if size < 8 && v >> (8 * size) != 0 {
                return None;
            }
            out.extend(&v.to_le_bytes()[..size]);
        }
        (Kind::Signed, size) => {
            let v: i64 = token.parse().ok()?;
            let bits = 8 * size as u32;
            if bits < 64 && (v < -(1i64 << (bits - 1)) || v >= 1i64 << (bits - 1)) {
                return None;
            }
            out.extend(&v.to_le_bytes()[..size]);
        }
    }
    Some(())
}

fn kind_letter(kind: Kind) -> char {
    match kind {
        Kind::Float => 'F',
        Kind::Signed => 'I',
        Kind::Unsigned => 'U',
    }
}

/// Unpacks a binary_compressed block after checking its two sizes against the header.
fn decompress(data: &[u8], header: &Header, name: &str) -> Result<Vec<u8>, FormatError> {
    let expected = header.points * header.record_size;
    let (Some(compressed), Some(unpacked)) = (read_u32(data, 0), read_u32(data, 4)) else {
        return Err(FormatError::malformed(
            name,
            format!(
                "binary_compressed data ends after {} bytes, before its 8-byte size prefix",
                data.len()
            ),
        ));
    };
    let (compressed, unpacked) = (compressed as usize, unpacked as usize);
    if unpacked != expected {
        return Err(FormatError::malformed(
            name,
            format!(
                "header says {} points of {} bytes ({expected} bytes) but the compressed block \
                 says it unpacks to {unpacked}",
                header.points, header.record_size
            ),
        ));
    }
    let block = &data[8..];
    if block.len() < compressed {
        return Err(FormatError::malformed(
            name,
            format!(
                "compressed block is {compressed} bytes but the file ends after {}",
                block.len()
            ),
        ));
    }
    if expected == 0 {
        return Ok(Vec::new());
    }
    // One LZF token of at most 3 bytes expands to at most 264, so a larger claim is a lie;
    // refusing it keeps a corrupt size from allocating gigabytes.
    if unpacked / 88 > compressed {
        return Err(FormatError::malformed(
            name,
            format!("{compressed} bytes of LZF data cannot unpack to {unpacked}"),
        ));
    }
    let records = lzf::decompress(&block[..compressed], unpacked).map_err(|e| {
        FormatError::malformed(
            name,
            format!("the LZF-compressed points are corrupt: {e:?}"),
        )
    })?;
    if records.len() != expected {
        return Err(FormatError::malformed(
            name,
            format!(
                "header says {} points ({expected} bytes) but the compressed block unpacks \
                 to {} bytes",
                header.points,
                records.len()
            ),
        ));
    }
    Ok(records)
}

fn read_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let b = bytes.get(at..at + 4)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// One value of a field as stored, with its type.
#[derive(Debug, Clone, Copy)]
struct Value<'a> {
    bytes: &'a [u8],
    kind: Kind,
}

impl Value<'_> {
    fn as_f64(self) -> f64 {
        let mut le = [0u8; 8];
        le[..self.bytes.len()].copy_from_slice(self.bytes);
        let size = self.bytes.len();
        match (self.kind, size) {
            (Kind::Float, 4) => f64::from(f32::from_le_bytes([le[0], le[1], le[2], le[3]])),
            (Kind::Float, _) => f64::from_le_bytes(le),
            (Kind::Unsigned, _) => u64::from_le_bytes(le) as f64,
            (Kind::Signed, _) => {
                // Sign-extend from the field's width.
                let shift = 64 - 8 * size as u32;
                ((i64::from_le_bytes(le) << shift) >> shift) as f64
            }
        }
    }

    /// The raw bits of a 4-byte value (checked by the caller).
    fn bits(self) -> u32 {
        let mut le = [0u8; 4];
        le.copy_from_slice(&self.bytes[..4]);
        u32::from_le_bytes(le)
    }
}

/// The first element of one field for every point, in point order. Always in bounds: `parse`
/// checked that the records hold every point before making columns.
struct Column<'a> {
    records: &'a [u8],
    field: &'a Field,
    /// Byte offset of point 0's value, and the distance between consecutive points.
    start: usize,
    stride: usize,
    n: usize,
    next: usize,
}

impl<'a> Column<'a> {
    fn new(records: &'a [u8], field: &'a Field, layout: Layout, header: &Header) -> Self {
        let n = header.points;
        let (start, stride) = match layout {
            Layout::RowMajor => (field.offset, header.record_size),
            Layout::ColumnMajor => (field.offset * n, field.size * field.count),
        };
        Self {
            records,
            field,
            start,
            stride,
            n,
            next: 0,
        }
    }
}

impl<'a> Iterator for Column<'a> {
    type Item = Value<'a>;

    fn next(&mut self) -> Option<Value<'a>> {
        if self.next == self.n {
            return None;
        }
        let at = self.start + self.next * self.stride;
        self.next += 1;
        Some(Value {
            bytes: self.records.get(at..at + self.field.size)?,
            kind: self.field.kind,
        })
    }
}

fn vectors(x: Column, y: Column, z: Column) -> Vec<Vec3> {
    x.zip(y)
        .zip(z)
        .map(|((x, y), z)| Vec3::new(x.as_f64() as f32, y.as_f64() as f32, z.as_f64() as f32))
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Entry points

/// Reads a PCD file, keeping its grid, labels and colours.
pub fn read_pcd(path: &Path) -> Result<PcdCloud, FormatError> {
    let name = path.display().to_string();
    let bytes =
        tacmesh_source::read_regular_file(path, crate::MAX_FILE_BYTES).map_err(|error| {
            FormatError::Io {
                name: name.clone(),
                action: "read",
                error,
            }
        })?;
    parse(&bytes, &name)
}

/// Parses a PCD held in memory. `name` is used in error messages.
pub fn parse(bytes: &[u8], name: &str) -> Result<PcdCloud, FormatError> {
    let header = parse_header(bytes, name)?;
    let data = &bytes[header.data_start..];
    let n = header.points;
    let (records, layout) = match header.data {
        DataKind::Ascii => (
            Cow::Owned(ascii_records(data, &header, name)?),
            Layout::RowMajor,
        ),
        DataKind::Binary => {
            let needed = n * header.record_size;
            if data.len() < needed {
                return Err(FormatError::malformed(
                    name,
                    format!(
                        "header says {n} points but the binary data ends after {} ({} bytes \
                         at {} bytes per point)",
                        data.len() / header.record_size,
                        data.len(),
                        header.record_size
                    ),
                ));
            }
            (Cow::Borrowed(&data[..needed]), Layout::RowMajor)
        }
        DataKind::BinaryCompressed => (
            Cow::Owned(decompress(data, &header, name)?),
            Layout::ColumnMajor,
        ),
    };

    let column = |field| Column::new(&records, field, layout, &header);
    let points = match (
        header.field("x", name)?,
        header.field("y", name)?,
        header.field("z", name)?,
    ) {
        (Some(x), Some(y), Some(z)) => vectors(column(x), column(y), column(z)),
        _ => {
            return Err(FormatError::malformed(
                name,
                format!("has no x y z fields (fields are: {})", header.field_names()),
            ))
        }
    };
    let normals = match (
        header.field("normal_x", name)?,
        header.field("normal_y", name)?,
        header.field("normal_z", name)?,
    ) {
        (Some(x), Some(y), Some(z)) => Some(vectors(column(x), column(y), column(z))),
        _ => None,
    };
    let labels = header
        .field("label", name)?
        .map(|f| column(f).map(|v| v.as_f64() as u32).collect());
    let rgba = match header.field("rgba", name)?.or(header.field("rgb", name)?) {
        Some(f) if f.size != 4 => {
            return Err(FormatError::malformed(
                name,
                format!("field {} has size {}; colours are 4 bytes", f.name, f.size),
            ))
        }
        Some(f) => Some(column(f).map(Value::bits).collect()),
        None => None,
    };
    Ok(PcdCloud {
        width: header.width,
        height: header.height,
        points,
        normals,
        labels,
        rgba,
        cloud_from_sensor: header.cloud_from_sensor,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(fields: &str, sizes: &str, types: &str, n: usize, data: &str) -> Vec<u8> {
        format!(
            "# comment\r\nVERSION .7\r\nFIELDS {fields}\r\nSIZE {sizes}\r\nTYPE {types}\r\n\
             WIDTH {n}\r\nHEIGHT 1\r\nPOINTS {n}\r\nDATA {data}\r\n"
        )
        .into_bytes()
    }

    #[test]
    fn crlf_header_and_signed_bytes_are_read() {
        let mut bytes = header("x y z", "1 2 4", "I I F", 1, "binary");
        bytes.push(-5i8 as u8);
        bytes.extend((-300i16).to_le_bytes());
        bytes.extend(0.25f32.to_le_bytes());
        let pcd = parse(&bytes, "s.pcd").unwrap();
        assert_eq!(pcd.points, vec![Vec3::new(-5.0, -300.0, 0.25)]);
    }

    #[test]
    fn ascii_value_too_large_for_its_field_is_rejected() {
        let mut bytes = header("x y z label", "4 4 4 1", "F F F U", 1, "ascii");
        bytes.extend(b"1 2 3 300\n");
        let err = parse(&bytes, "l.pcd").unwrap_err().to_string();
        assert_eq!(
            err,
            "l.pcd: line 10: \"300\" is not a valid label (TYPE U SIZE 1)"
        );
    }

    #[test]
    fn coordinate_with_count_above_one_is_rejected() {
        let mut bytes = header("x y z", "4 4 4", "F F F", 1, "ascii");
        bytes.splice(0..0, b"COUNT 2 1 1\n".iter().copied());
        bytes.extend(b"1 1 2 3\n");
        let err = parse(&bytes, "c.pcd").unwrap_err().to_string();
        assert_eq!(err, "c.pcd: field x has COUNT 2; expected 1");
    }

    /// Found by fuzzing (`fuzz/`, target `pcd`): the ascii reader reserved POINTS × record
    /// size before reading a line, so a histogram field with a COUNT of 10^15 asked for
    /// 10^17 bytes and aborted the process.
    #[test]
    fn ascii_pcd_with_huge_count_is_an_error_not_an_allocation() {
        let mut bytes = header("x y z h", "4 4 4 8", "F F F F", 11, "ascii");
        bytes.splice(0..0, b"COUNT 1 1 1 1888888888888888\n".iter().copied());
        bytes.extend(b"1 2 3 4\n".repeat(11));
        let err = parse(&bytes, "n.pcd").unwrap_err().to_string();
        assert_eq!(err, "n.pcd: line 11 ends before field h");
    }

    #[test]
    fn viewpoint_line_gives_the_sensor_pose() {
        let mut bytes = header("x y z", "4 4 4", "F F F", 0, "ascii");
        bytes.splice(0..0, b"VIEWPOINT 1 2 -3 0 1 0 0\n".iter().copied());
        let pose = parse(&bytes, "v.pcd").unwrap().cloud_from_sensor.unwrap();
        assert_eq!(pose.translation, Vec3::new(1.0, 2.0, -3.0).into());
        // qw = 0, qx = 1: half a turn about x.
        assert!(pose.transform_vector3(Vec3::Y).abs_diff_eq(-Vec3::Y, 1e-6));
    }

    #[test]
    fn header_without_viewpoint_has_no_sensor_pose() {
        let bytes = header("x y z", "4 4 4", "F F F", 0, "ascii");
        assert_eq!(parse(&bytes, "n.pcd").unwrap().cloud_from_sensor, None);
    }

    #[test]
    fn viewpoint_with_six_numbers_is_rejected() {
        let mut bytes = header("x y z", "4 4 4", "F F F", 0, "ascii");
        bytes.splice(0..0, b"VIEWPOINT 0 0 0 1 0 0\n".iter().copied());
        let err = parse(&bytes, "s.pcd").unwrap_err().to_string();
        assert_eq!(
            err,
            "s.pcd: header line 1 (VIEWPOINT): expected 7 numbers (tx ty tz qw qx qy qz), got 6"
        );
    }

    #[test]
    fn half_precision_floats_are_rejected() {
        let bytes = header("x y z", "2 4 4", "F F F", 0, "ascii");
        let err = parse(&bytes, "h.pcd").unwrap_err().to_string();
        assert_eq!(err, "h.pcd: header: field x is TYPE F with SIZE 2");
    }

    #[test]
    fn header_without_data_line_is_rejected() {
        let bytes = b"VERSION .7\nFIELDS x y z\n";
        let err = parse(bytes, "t.pcd").unwrap_err().to_string();
        assert_eq!(
            err,
            "t.pcd: the header ends after line 2 without a DATA line"
        );
    }
}
