//! PLY, the Stanford polygon format: a text header declaring elements and their properties,
//! then the elements in ascii, binary little-endian or binary big-endian. The header and binary
//! payloads are parsed, and files written, with `ply-rs-bw`; ascii payloads are read here, so
//! that `nan` and `inf` are numbers as in every other format.
//!
//! Entry points:
//! - [`parse_cloud`]: the `vertex` element's x y z (float or double), and nx ny nz when all
//!   three are present.
//! - [`parse_mesh`]: `vertex` plus `face`, whose `vertex_indices` (or `vertex_index`) lists of
//!   any integer type are fan-triangulated.
//! - [`write_cloud`], [`write_mesh`]: binary little-endian, x y z as float, faces as
//!   `list uchar uint vertex_indices`.
//!
//! Other elements (a scanner's `range_grid`, say) and properties (colours, confidence) are
//! read past and dropped. Before the payload is parsed the header's element counts are checked
//! against the bytes that follow it, so a truncated file is an error naming what is missing,
//! and a corrupt count cannot make the parser loop or allocate without end.

use std::io::{self, Cursor, Write};

use glam::Vec3;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    Addable, BeginList, ElementDef, Encoding, Header, PropertyAccess, PropertyAccessResult,
    PropertyDef, PropertyType, ScalarType, Version,
};
use ply_rs_bw::writer::Writer;
use tacmesh_source::{PointCloud, TriMesh};

use crate::FormatError;

const POSITION_NAMES: [&str; 3] = ["x", "y", "z"];
const NORMAL_NAMES: [&str; 3] = ["nx", "ny", "nz"];
const FACE_INDEX_NAMES: [&str; 2] = ["vertex_indices", "vertex_index"];

/// One `vertex` element: position and normal, every other property ignored.
#[derive(Debug, Default, Clone, Copy)]
struct VertexRecord {
    position: [f32; 3],
    normal: [f32; 3],
}

impl VertexRecord {
    /// The coordinate a property name stands for: `(normal?, axis)`.
    fn axis(property: &str) -> Option<(bool, usize)> {
        let position = POSITION_NAMES.iter().position(|&n| n == property);
        let normal = NORMAL_NAMES.iter().position(|&n| n == property);
        position.map(|a| (false, a)).or(normal.map(|a| (true, a)))
    }

    fn set(&mut self, property: &str, value: f32) -> PropertyAccessResult {
        match Self::axis(property) {
            Some((false, a)) => self.position[a] = value,
            Some((true, a)) => self.normal[a] = value,
            None => return PropertyAccessResult::Ignored,
        }
        PropertyAccessResult::Set
    }
}

impl PropertyAccess for VertexRecord {
    fn new() -> Self {
        Self::default()
    }

    fn set_float(&mut self, property: &str, value: f32) -> PropertyAccessResult {
        self.set(property, value)
    }

    fn set_double(&mut self, property: &str, value: f64) -> PropertyAccessResult {
        self.set(property, value as f32)
    }

    fn get_float(&self, property: &str) -> Option<f32> {
        match Self::axis(property)? {
            (false, a) => Some(self.position[a]),
            (true, a) => Some(self.normal[a]),
        }
    }
}

/// One `vertex` element of a cloud without normals: its position only, every other property
/// ignored. Twelve bytes like the [`Vec3`] it becomes, so the records turn into the cloud's
/// points in place: a large cloud is held once while it is read, not three times (file,
/// records, points).
#[derive(Debug, Default, Clone, Copy)]
struct PositionRecord([f32; 3]);

impl PositionRecord {
    /// The axis a position property stands for (a normal's is ignored here).
    fn axis(property: &str) -> Option<usize> {
        match VertexRecord::axis(property)? {
            (false, axis) => Some(axis),
            (true, _) => None,
        }
    }

    fn set(&mut self, property: &str, value: f32) -> PropertyAccessResult {
        match Self::axis(property) {
            Some(axis) => {
                self.0[axis] = value;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }
}

impl PropertyAccess for PositionRecord {
    fn new() -> Self {
        Self::default()
    }

    fn set_float(&mut self, property: &str, value: f32) -> PropertyAccessResult {
        self.set(property, value)
    }

    fn set_double(&mut self, property: &str, value: f64) -> PropertyAccessResult {
        self.set(property, value as f32)
    }

    fn get_float(&self, property: &str) -> Option<f32> {
        Some(self.0[Self::axis(property)?])
    }
}

/// One `face` element as read: its corner indices, every other property ignored.
#[derive(Debug, Default)]
struct FaceRecord {
    indices: Vec<u32>,
    /// Set when a signed index list held a negative value.
    has_negative_index: bool,
}

impl FaceRecord {
    fn set_signed(&mut self, property: &str, values: &[i64]) -> PropertyAccessResult {
        if !FACE_INDEX_NAMES.contains(&property) {
            return PropertyAccessResult::Ignored;
        }
        self.has_negative_index = values.iter().any(|&v| v < 0);
        self.indices = values.iter().map(|&v| v.max(0) as u32).collect();
        PropertyAccessResult::Set
    }

    fn set_unsigned(&mut self, property: &str, values: &[u32]) -> PropertyAccessResult {
        if !FACE_INDEX_NAMES.contains(&property) {
            return PropertyAccessResult::Ignored;
        }
        self.indices = values.to_vec();
        PropertyAccessResult::Set
    }
}

impl PropertyAccess for FaceRecord {
    fn new() -> Self {
        Self::default()
    }

    fn set_list_char(&mut self, property: &str, values: Vec<i8>) -> PropertyAccessResult {
        let values: Vec<i64> = values.into_iter().map(i64::from).collect();
        self.set_signed(property, &values)
    }

    fn set_list_uchar(&mut self, property: &str, values: Vec<u8>) -> PropertyAccessResult {
        let values: Vec<u32> = values.into_iter().map(u32::from).collect();
        self.set_unsigned(property, &values)
    }

    fn set_list_short(&mut self, property: &str, values: Vec<i16>) -> PropertyAccessResult {
        let values: Vec<i64> = values.into_iter().map(i64::from).collect();
        self.set_signed(property, &values)
    }

    fn set_list_ushort(&mut self, property: &str, values: Vec<u16>) -> PropertyAccessResult {
        let values: Vec<u32> = values.into_iter().map(u32::from).collect();
        self.set_unsigned(property, &values)
    }

    fn set_list_int(&mut self, property: &str, values: Vec<i32>) -> PropertyAccessResult {
        let values: Vec<i64> = values.into_iter().map(i64::from).collect();
        self.set_signed(property, &values)
    }

    fn set_list_uint(&mut self, property: &str, values: Vec<u32>) -> PropertyAccessResult {
        self.set_unsigned(property, &values)
    }

    fn begin_list_uint(&mut self, property: &str, _len: usize) -> BeginList<'_, u32> {
        if FACE_INDEX_NAMES.contains(&property) {
            BeginList::Fill(&mut self.indices)
        } else {
            BeginList::UseSetter
        }
    }
}

/// One triangle as written.
#[derive(Debug, Default, Clone, Copy)]
struct TriangleRecord([u32; 3]);

impl PropertyAccess for TriangleRecord {
    fn new() -> Self {
        Self::default()
    }

    fn get_list_uint(&self, _property: &str) -> Option<&[u32]> {
        Some(&self.0)
    }
}

/// An element this crate does not use; parsed only to get past it.
#[derive(Debug)]
struct Ignored;

impl PropertyAccess for Ignored {
    fn new() -> Self {
        Ignored
    }
}

/// What [`read`] found.
struct Contents<V> {
    vertices: Vec<V>,
    /// `None` unless faces were asked for.
    faces: Option<Vec<FaceRecord>>,
}

/// Checks the declared element counts against the payload: at least one line per ascii
/// element, at least the fixed-size part of each binary element. This catches truncation
/// with a clear message and bounds the work a corrupt count can cause.
fn check_counts(header: &Header, body: &[u8], name: &str) -> Result<(), FormatError> {
    for (element_name, def) in &header.elements {
        if def.count > 0 && def.properties.is_empty() {
            return Err(FormatError::malformed(
                name,
                format!(
                    "element {element_name} declares {} items but no properties",
                    def.count
                ),
            ));
        }
    }
    let declared = || {
        header
            .elements
            .iter()
            .map(|(n, def)| format!("{} {n}", def.count))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if header.encoding == Encoding::Ascii {
        let needed_lines = header
            .elements
            .values()
            .fold(0usize, |sum, def| sum.saturating_add(def.count));
        let lines = body
            .split(|&b| b == b'\n')
            .filter(|l| !l.is_empty())
            .count();
        if lines < needed_lines {
            return Err(FormatError::malformed(
                name,
                format!(
                    "header declares {} ({needed_lines} lines) but only {lines} lines follow it",
                    declared()
                ),
            ));
        }
    } else {
        let needed_bytes = header.elements.values().fold(0usize, |sum, def| {
            let per_item: usize = def
                .properties
                .values()
                .map(|p| match &p.data_type {
                    PropertyType::Scalar(t) | PropertyType::List(t, _) => scalar_size(t),
                })
                .sum();
            sum.saturating_add(def.count.saturating_mul(per_item))
        });
        if body.len() < needed_bytes {
            return Err(FormatError::malformed(
                name,
                format!(
                    "header declares {} (at least {needed_bytes} bytes) but the binary data \
                     ends after {} bytes",
                    declared(),
                    body.len()
                ),
            ));
        }
    }
    Ok(())
}

/// Checks that there is a `vertex` element with x y z stored as float or double; returns
/// whether it has nx ny nz too.
fn check_vertex_element(header: &Header, name: &str) -> Result<bool, FormatError> {
    let Some(vertex) = header.elements.get("vertex") else {
        return Err(FormatError::malformed(name, "has no vertex element"));
    };
    let real_property = |property: &str| match vertex.properties.get(property) {
        Some(p) => match p.data_type {
            PropertyType::Scalar(ScalarType::Float | ScalarType::Double) => Ok(true),
            ref other => Err(FormatError::malformed(
                name,
                format!(
                    "vertex property {property} is {}; expected float or double",
                    type_name(other)
                ),
            )),
        },
        None => Ok(false),
    };
    for axis in POSITION_NAMES {
        if !real_property(axis)? {
            return Err(FormatError::malformed(
                name,
                format!("vertex element has no {axis} property"),
            ));
        }
    }
    let mut normals = 0;
    for axis in NORMAL_NAMES {
        normals += usize::from(real_property(axis)?);
    }
    Ok(normals == 3)
}

/// Checks that there is a `face` element whose corner list has an integer type.
fn check_face_element(header: &Header, name: &str) -> Result<(), FormatError> {
    let Some(face) = header.elements.get("face") else {
        return Err(FormatError::malformed(
            name,
            "has no face element: it is a point cloud, not a mesh",
        ));
    };
    let Some(indices) = FACE_INDEX_NAMES
        .iter()
        .find_map(|n| face.properties.get(*n))
    else {
        return Err(FormatError::malformed(
            name,
            "face element has no vertex_indices (or vertex_index) property",
        ));
    };
    match &indices.data_type {
        PropertyType::List(_, ScalarType::Float | ScalarType::Double) | PropertyType::Scalar(_) => {
            Err(FormatError::malformed(
                name,
                format!(
                    "face property {} is {}; expected a list of integers",
                    indices.name,
                    type_name(&indices.data_type)
                ),
            ))
        }
        PropertyType::List(..) => Ok(()),
    }
}

/// The type as a PLY header spells it.
fn type_name(t: &PropertyType) -> String {
    let scalar = |t: &ScalarType| match t {
        ScalarType::Char => "char",
        ScalarType::UChar => "uchar",
        ScalarType::Short => "short",
        ScalarType::UShort => "ushort",
        ScalarType::Int => "int",
        ScalarType::UInt => "uint",
        ScalarType::Float => "float",
        ScalarType::Double => "double",
    };
    match t {
        PropertyType::Scalar(t) => scalar(t).to_owned(),
        PropertyType::List(count, item) => format!("list {} {}", scalar(count), scalar(item)),
    }
}

fn scalar_size(t: &ScalarType) -> usize {
    match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    }
}

// ---------------------------------------------------------------------------------------------
// Ascii payload. `ply-rs-bw`'s grammar takes only digits, signs, a point and an exponent, so
// it refuses `nan`, `inf`, `.5` and `1.`, which scanners and numpy write; this reader takes
// every number Rust's parsers take, so that a non-finite point reads as one (and is dropped
// by `read_cloud` like a binary file's) instead of failing the file.

/// The non-blank lines of an ascii payload with their line numbers in the file.
struct AsciiLines<'a> {
    rest: &'a [u8],
    /// The number in the file of the first line of `rest`.
    line_number: usize,
}

impl<'a> AsciiLines<'a> {
    fn new(body: &'a [u8], first_line: usize) -> Self {
        Self {
            rest: body,
            line_number: first_line,
        }
    }

    /// The next non-blank line and its number; `Ok(None)` at the end.
    fn next_line(&mut self, name: &str) -> Result<Option<(usize, &'a str)>, FormatError> {
        while !self.rest.is_empty() {
            let end = self
                .rest
                .iter()
                .position(|&b| b == b'\n')
                .unwrap_or(self.rest.len());
            let (line, number) = (&self.rest[..end], self.line_number);
            self.rest = self.rest.get(end + 1..).unwrap_or_default();
            self.line_number += 1;
            let text = std::str::from_utf8(line)
                .map_err(|_| FormatError::malformed(name, format!("line {number} is not text")))?;
            if !text.trim().is_empty() {
                return Ok(Some((number, text)));
            }
        }
        Ok(None)
    }
}

/// Reads `def.count` lines of one element, each its properties in header order (a list as its
/// length, then its items). Tokens after the last property are ignored, as `ply-rs-bw` does.
fn read_ascii_element<E: PropertyAccess>(
    lines: &mut AsciiLines,
    element_name: &str,
    def: &ElementDef,
    name: &str,
) -> Result<Vec<E>, FormatError> {
    // `check_counts` found a line per item, so `count` is bounded by the file's size.
    let mut records = Vec::with_capacity(def.count);
    for item in 0..def.count {
        let Some((line_number, text)) = lines.next_line(name)? else {
            return Err(FormatError::malformed(
                name,
                format!(
                    "the file ends after {item} of the {} {element_name} lines its header declares",
                    def.count
                ),
            ));
        };
        let mut tokens = text.split_whitespace();
        let mut record = E::new();
        for (property, p) in &def.properties {
            let bad = |token: Option<&str>, what: &str| {
                FormatError::malformed(
                    name,
                    match token {
                        Some(token) => format!(
                            "line {line_number}: {token:?} is not a valid {what} for \
                             {element_name} property {property} ({})",
                            type_name(&p.data_type)
                        ),
                        None => format!(
                            "line {line_number} ends before {element_name} property {property}"
                        ),
                    },
                )
            };
            match &p.data_type {
                PropertyType::Scalar(t) => {
                    let token = tokens.next();
                    set_ascii_scalar(&mut record, property, t, token.unwrap_or_default())
                        .ok_or_else(|| bad(token, "value"))?;
                }
                PropertyType::List(count_type, item_type) => {
                    let token = tokens.next();
                    let len = token
                        .and_then(|t| list_length(t, count_type))
                        .ok_or_else(|| bad(token, "list length"))?;
                    let items: Vec<&str> = tokens.by_ref().take(len as usize).collect();
                    if (items.len() as u64) < len {
                        return Err(FormatError::malformed(
                            name,
                            format!(
                                "line {line_number}: {element_name} property {property} \
                                 declares {len} items but the line has {}",
                                items.len()
                            ),
                        ));
                    }
                    set_ascii_list(&mut record, property, item_type, &items)
                        .map_err(|token| bad(Some(token), "list item"))?;
                }
            }
        }
        records.push(record);
    }
    Ok(records)
}

/// A list's length as written, if it is a whole number the count type holds.
fn list_length(token: &str, count_type: &ScalarType) -> Option<u64> {
    let len: u64 = token.parse().ok()?;
    let bits = 8 * scalar_size(count_type) as u32;
    let signed = matches!(
        count_type,
        ScalarType::Char | ScalarType::Short | ScalarType::Int
    );
    // A shift by 64 (a `double` count, which only a strange file has) is no bound at all.
    let over = len.checked_shr(bits - u32::from(signed)).unwrap_or(0);
    (over == 0).then_some(len)
}

/// Parses `token` as `t` and hands it to the record; `None` if it does not parse.
fn set_ascii_scalar<E: PropertyAccess>(
    record: &mut E,
    property: &str,
    t: &ScalarType,
    token: &str,
) -> Option<()> {
    match t {
        ScalarType::Char => record.set_char(property, token.parse().ok()?),
        ScalarType::UChar => record.set_uchar(property, token.parse().ok()?),
        ScalarType::Short => record.set_short(property, token.parse().ok()?),
        ScalarType::UShort => record.set_ushort(property, token.parse().ok()?),
        ScalarType::Int => record.set_int(property, token.parse().ok()?),
        ScalarType::UInt => record.set_uint(property, token.parse().ok()?),
        ScalarType::Float => record.set_float(property, token.parse().ok()?),
        ScalarType::Double => record.set_double(property, token.parse().ok()?),
    };
    Some(())
}

/// Parses every token as `t` and hands the list to the record; the first bad token on error.
fn set_ascii_list<'t, E: PropertyAccess>(
    record: &mut E,
    property: &str,
    t: &ScalarType,
    tokens: &[&'t str],
) -> Result<(), &'t str> {
    fn all<'t, T: std::str::FromStr>(tokens: &[&'t str]) -> Result<Vec<T>, &'t str> {
        tokens.iter().map(|t| t.parse().map_err(|_| *t)).collect()
    }
    match t {
        ScalarType::Char => record.set_list_char(property, all(tokens)?),
        ScalarType::UChar => record.set_list_uchar(property, all(tokens)?),
        ScalarType::Short => record.set_list_short(property, all(tokens)?),
        ScalarType::UShort => record.set_list_ushort(property, all(tokens)?),
        ScalarType::Int => record.set_list_int(property, all(tokens)?),
        ScalarType::UInt => record.set_list_uint(property, all(tokens)?),
        ScalarType::Float => record.set_list_float(property, all(tokens)?),
        ScalarType::Double => record.set_list_double(property, all(tokens)?),
    };
    Ok(())
}

/// A reader of a PLY held in memory.
type BytesReader<'a> = Reader<Cursor<&'a [u8]>>;

/// The header, and a reader at the first byte after it.
fn read_header<'a>(bytes: &'a [u8], name: &str) -> Result<(Header, BytesReader<'a>), FormatError> {
    // Said plainly before the parser's own words (an empty file's "Unexpected end of file
    // while reading magic number", random bytes' "stream did not contain valid UTF-8").
    if bytes.is_empty() {
        return Err(FormatError::malformed(name, "the file is empty"));
    }
    if !(bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n")) {
        return Err(FormatError::malformed(
            name,
            "not a PLY file: it does not begin with the line `ply`",
        ));
    }
    let mut reader = Reader::new(Cursor::new(bytes));
    let header = Parser::<Ignored>::new()
        .read_header(&mut reader)
        .map_err(|e| ply_error(name, &e))?;
    Ok((header, reader))
}

/// Reads the header, checks it against the bytes after it, then parses every element in
/// order: `vertex` into records, `face` too when `faces_wanted`, the rest only to skip them.
fn read<V: PropertyAccess>(
    bytes: &[u8],
    name: &str,
    faces_wanted: bool,
) -> Result<Contents<V>, FormatError> {
    let (header, reader) = read_header(bytes, name)?;
    let body = bytes
        .get(reader.get_ref().position() as usize..)
        .unwrap_or_default();
    check_counts(&header, body, name)?;
    check_vertex_element(&header, name)?;
    if faces_wanted {
        check_face_element(&header, name)?;
    }

    let mut payload = if header.encoding == Encoding::Ascii {
        let header_lines = bytes[..bytes.len() - body.len()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        Payload::Ascii(AsciiLines::new(body, header_lines + 1))
    } else {
        Payload::Binary(reader)
    };
    let mut vertices = Vec::new();
    let mut faces = faces_wanted.then(Vec::new);
    for (element_name, def) in &header.elements {
        match (element_name.as_str(), &mut faces) {
            ("vertex", _) => vertices = payload.element(element_name, def, &header, name)?,
            ("face", Some(faces)) => *faces = payload.element(element_name, def, &header, name)?,
            _ => {
                payload.element::<Ignored>(element_name, def, &header, name)?;
            }
        }
    }
    payload.note_leftover(bytes.len(), name)?;
    Ok(Contents { vertices, faces })
}

/// Where the elements come from: ascii lines, read here; binary records, read by `ply-rs-bw`.
enum Payload<'a> {
    Ascii(AsciiLines<'a>),
    Binary(BytesReader<'a>),
}

impl Payload<'_> {
    /// The next element's records.
    fn element<E: PropertyAccess>(
        &mut self,
        element_name: &str,
        def: &ElementDef,
        header: &Header,
        name: &str,
    ) -> Result<Vec<E>, FormatError> {
        match self {
            Payload::Ascii(lines) => read_ascii_element(lines, element_name, def, name),
            Payload::Binary(reader) => Parser::<E>::new()
                .read_payload_for_element(reader, def, header)
                .map_err(|e| ply_error(name, &e)),
        }
    }

    /// Logs what follows the last element (ignored, as `ply-rs-bw` ignores it).
    fn note_leftover(&mut self, file_len: usize, name: &str) -> Result<(), FormatError> {
        match self {
            Payload::Ascii(lines) => {
                if let Some((line_number, _)) = lines.next_line(name)? {
                    tracing::debug!(
                        "{name}: ignored the lines from {line_number} on, after the last element"
                    );
                }
            }
            Payload::Binary(reader) => {
                let unread = file_len as u64 - reader.get_ref().position();
                if unread > 0 {
                    tracing::debug!("{name}: ignored {unread} bytes after the last element");
                }
            }
        }
        Ok(())
    }
}

/// A `ply-rs-bw` error about the file `name`, in one line.
fn ply_error(name: &str, error: &ply_rs_bw::parser::ParseError) -> FormatError {
    FormatError::malformed(name, one_line(&error.to_string()))
}

/// `ply-rs-bw` messages span several tab-indented lines, and header errors end in a dump of
/// the grammar's expected tokens; error messages here are one line without the dump.
fn one_line(message: &str) -> String {
    let mut line = message.split_whitespace().collect::<Vec<_>>().join(" ");
    if let Some(dump) = line.find(" Error: ParseError {") {
        line.truncate(dump);
    }
    line
}

/// Parses the `vertex` element of a PLY held in memory, in file order, non-finite points
/// included. `name` is used in error messages.
pub fn parse_cloud(bytes: &[u8], name: &str) -> Result<PointCloud, FormatError> {
    let (header, _) = read_header(bytes, name)?;
    if !check_vertex_element(&header, name)? {
        let contents = read::<PositionRecord>(bytes, name, false)?;
        // Same size and alignment: collected in place, no second buffer.
        let points: Vec<Vec3> = contents
            .vertices
            .into_iter()
            .map(|PositionRecord(p)| Vec3::from(p))
            .collect();
        return Ok(PointCloud::new(points));
    }
    let contents = read::<VertexRecord>(bytes, name, false)?;
    let points = contents
        .vertices
        .iter()
        .map(|v| Vec3::from(v.position))
        .collect();
    let normals = contents
        .vertices
        .iter()
        .map(|v| Vec3::from(v.normal))
        .collect();
    Ok(PointCloud::with_normals(points, normals))
}

/// Parses a PLY mesh held in memory: vertices in file order, each face of n corners as the
/// n - 2 triangles of a fan from its first corner. `name` is used in error messages.
pub fn parse_mesh(bytes: &[u8], name: &str) -> Result<TriMesh, FormatError> {
    let contents = read::<VertexRecord>(bytes, name, true)?;
    let vertex_count = contents.vertices.len();
    let mut triangles = Vec::new();
    for (f, face) in contents.faces.unwrap_or_default().iter().enumerate() {
        if face.has_negative_index {
            return Err(FormatError::malformed(
                name,
                format!("face {f} has a negative vertex index"),
            ));
        }
        if face.indices.len() < 3 {
            return Err(FormatError::malformed(
                name,
                format!(
                    "face {f} has {} corners; a face needs at least 3",
                    face.indices.len()
                ),
            ));
        }
        if let Some(&bad) = face.indices.iter().find(|&&i| i as usize >= vertex_count) {
            return Err(FormatError::malformed(
                name,
                format!("face {f} refers to vertex {bad} but there are {vertex_count} vertices"),
            ));
        }
        let first = face.indices[0];
        triangles.extend(face.indices[1..].windows(2).map(|w| [first, w[0], w[1]]));
    }
    let vertices = contents
        .vertices
        .iter()
        .map(|v| Vec3::from(v.position))
        .collect();
    Ok(TriMesh::new(vertices, triangles))
}

fn vertex_element(count: usize, with_normals: bool) -> ElementDef {
    let mut def = ElementDef::new("vertex".to_owned());
    def.count = count;
    let names = if with_normals {
        [POSITION_NAMES, NORMAL_NAMES].concat()
    } else {
        POSITION_NAMES.to_vec()
    };
    for property in names {
        def.properties.add(PropertyDef::new(
            property.to_owned(),
            PropertyType::Scalar(ScalarType::Float),
        ));
    }
    def
}

fn binary_header<const N: usize>(elements: [ElementDef; N]) -> Header {
    let mut header = Header::new();
    header.encoding = Encoding::BinaryLittleEndian;
    header.version = Version { major: 1, minor: 0 };
    for element in elements {
        header.elements.add(element);
    }
    header
}

/// Writes a cloud as binary little-endian PLY: `x y z` float, plus `nx ny nz` when the cloud
/// has normals (one per point; the caller checks).
pub fn write_cloud<W: Write>(out: &mut W, cloud: &PointCloud) -> io::Result<()> {
    let vertices: Vec<VertexRecord> = match &cloud.normals {
        Some(normals) => cloud
            .points
            .iter()
            .zip(normals)
            .map(|(p, n)| VertexRecord {
                position: p.to_array(),
                normal: n.to_array(),
            })
            .collect(),
        None => cloud
            .points
            .iter()
            .map(|p| VertexRecord {
                position: p.to_array(),
                normal: [0.0; 3],
            })
            .collect(),
    };
    let vertex_def = vertex_element(vertices.len(), cloud.normals.is_some());
    let header = binary_header([vertex_def.clone()]);
    let writer = Writer::<VertexRecord>::new();
    writer.write_header(out, &header)?;
    writer.write_payload_of_element(out, &vertices, &vertex_def, &header)?;
    Ok(())
}

/// Writes a mesh as binary little-endian PLY: a `vertex` element with `x y z` float and a
/// `face` element with `list uchar uint vertex_indices`. The caller checks the indices.
///
/// `ply-rs-bw` writes binary face lists correctly (the older `ply-rs` 0.1.3 did not); the
/// round-trip tests in this crate pin that down.
pub fn write_mesh<W: Write>(out: &mut W, mesh: &TriMesh) -> io::Result<()> {
    let vertices: Vec<VertexRecord> = mesh
        .vertices
        .iter()
        .map(|p| VertexRecord {
            position: p.to_array(),
            normal: [0.0; 3],
        })
        .collect();
    let triangles: Vec<TriangleRecord> =
        mesh.triangles.iter().map(|&t| TriangleRecord(t)).collect();
    let vertex_def = vertex_element(vertices.len(), false);
    let mut face_def = ElementDef::new("face".to_owned());
    face_def.count = triangles.len();
    face_def.properties.add(PropertyDef::new(
        FACE_INDEX_NAMES[0].to_owned(),
        PropertyType::List(ScalarType::UChar, ScalarType::UInt),
    ));
    let header = binary_header([vertex_def.clone(), face_def.clone()]);
    Writer::<VertexRecord>::new().write_header(out, &header)?;
    Writer::<VertexRecord>::new().write_payload_of_element(out, &vertices, &vertex_def, &header)?;
    Writer::<TriangleRecord>::new()
        .write_payload_of_element(out, &triangles, &face_def, &header)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASCII_QUAD: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n\
        property float y\nproperty float z\nelement face 1\n\
        property list uchar int vertex_indices\nend_header\n\
        0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";

    #[test]
    fn quad_is_fanned_into_two_triangles() {
        let mesh = parse_mesh(ASCII_QUAD.as_bytes(), "quad.ply").unwrap();
        assert_eq!(mesh.vertices.len(), 4);
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    /// An empty file and one of random bytes are said to be so, in words, not in the parser's.
    #[test]
    fn empty_and_random_files_are_named_plainly() {
        let empty = parse_cloud(b"", "e.ply").unwrap_err().to_string();
        assert!(
            empty.contains("e.ply") && empty.contains("empty"),
            "{empty}"
        );
        let random: Vec<u8> = (0..512u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 7) as u8)
            .collect();
        let junk = parse_mesh(&random, "r.ply").unwrap_err().to_string();
        assert!(junk.contains("not a PLY file"), "{junk}");
        assert!(!junk.contains("UTF-8"), "{junk}");
    }

    #[test]
    fn double_coordinates_and_normals_are_read() {
        let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty double x\n\
            property double y\nproperty double z\nproperty float nx\nproperty float ny\n\
            property float nz\nproperty uchar red\nend_header\n1.5 2.5 3.5 0 0 1 255\n";
        let cloud = parse_cloud(text.as_bytes(), "n.ply").unwrap();
        assert_eq!(cloud.points, vec![Vec3::new(1.5, 2.5, 3.5)]);
        assert_eq!(cloud.normals, Some(vec![Vec3::Z]));
    }

    #[test]
    fn big_endian_ushort_index_list_is_read() {
        let mut bytes = b"ply\nformat binary_big_endian 1.0\nelement vertex 3\n\
            property float x\nproperty float y\nproperty float z\nelement face 1\n\
            property list uchar ushort vertex_index\nend_header\n"
            .to_vec();
        for p in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
            for c in p {
                bytes.extend(c.to_be_bytes());
            }
        }
        bytes.push(3);
        for i in [2u16, 1, 0] {
            bytes.extend(i.to_be_bytes());
        }
        let mesh = parse_mesh(&bytes, "be.ply").unwrap();
        assert_eq!(mesh.vertices[1], Vec3::X);
        assert_eq!(mesh.triangles, vec![[2, 1, 0]]);
    }

    #[test]
    fn face_index_out_of_range_is_rejected() {
        let text = ASCII_QUAD.replace("4 0 1 2 3", "4 0 1 2 900");
        let err = parse_mesh(text.as_bytes(), "x.ply")
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "x.ply: face 0 refers to vertex 900 but there are 4 vertices"
        );
    }

    #[test]
    fn negative_face_index_is_rejected() {
        let text = ASCII_QUAD.replace("4 0 1 2 3", "4 0 1 2 -1");
        let err = parse_mesh(text.as_bytes(), "x.ply")
            .unwrap_err()
            .to_string();
        assert!(err.contains("negative"), "{err}");
    }

    #[test]
    fn missing_lines_are_counted_before_parsing() {
        let text = ASCII_QUAD.replace("0 1 0\n4 0 1 2 3\n", "");
        let err = parse_mesh(text.as_bytes(), "x.ply")
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "x.ply: header declares 4 vertex, 1 face (5 lines) but only 3 lines follow it"
        );
    }

    #[test]
    fn integer_coordinates_are_rejected() {
        let text = ASCII_QUAD.replace("property float y", "property int y");
        let err = parse_cloud(text.as_bytes(), "x.ply")
            .unwrap_err()
            .to_string();
        assert!(err.contains("vertex property y is"), "{err}");
    }

    #[test]
    fn ascii_nan_inf_and_bare_decimal_points_are_numbers() {
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
            property float y\nproperty double z\nend_header\n.5 1. -2\nNaN 0 0\n\n0 -inf +1e3\n";
        let cloud = parse_cloud(text.as_bytes(), "n.ply").unwrap();
        assert_eq!(cloud.points[0], Vec3::new(0.5, 1.0, -2.0));
        assert!(cloud.points[1].x.is_nan());
        assert_eq!(cloud.points[2], Vec3::new(0.0, f32::NEG_INFINITY, 1000.0));
    }

    #[test]
    fn ascii_word_is_rejected_with_its_line_and_property() {
        let text = ASCII_QUAD.replace("1 1 0", "1 one 0");
        let err = parse_mesh(text.as_bytes(), "w.ply")
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "w.ply: line 12: \"one\" is not a valid value for vertex property y (float)"
        );
    }

    #[test]
    fn ascii_face_shorter_than_its_length_is_rejected() {
        let text = ASCII_QUAD.replace("4 0 1 2 3", "4 0 1 2");
        let err = parse_mesh(text.as_bytes(), "f.ply")
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "f.ply: line 14: face property vertex_indices declares 4 items but the line has 3"
        );
    }

    #[test]
    fn cloud_file_is_not_a_mesh() {
        let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n\
            property float y\nproperty float z\nend_header\n1 2 3\n";
        let err = parse_mesh(text.as_bytes(), "c.ply")
            .unwrap_err()
            .to_string();
        assert!(err.contains("no face element"), "{err}");
    }
}
