//! Wavefront OBJ meshes with MTL materials and textures, via `tobj`.
//!
//! Faces are triangulated (fans); each OBJ object/group and material becomes one mesh with one
//! index per vertex. MTL: `Kd` diffuse colour, `map_Kd` diffuse texture (sRGB, multiplied by
//! `Kd` when both are given), `Ks` specular colour, `Ns` shininess; `illum` 3, 5 or 7 (ray-traced
//! reflection) makes the surface a mirror of strength `max(Ks)`.

use std::cell::{Cell, RefCell};
use std::io::{BufRead, Read};
use std::path::{Path, PathBuf};

use glam::Vec3;

use super::MAX_MATERIAL_VALUE;
use super::error::{LoadError, Location};
use super::input::{self, LoadOptions};
use super::mesh_input::{MeshBuffers, ModelFile, buffer, guarded, keep_winding, memory_error};
use super::model::{Model, ModelMesh, Transform, short_vec};
use super::texture::TextureCache;
use crate::limits::check_budget;
use crate::shade::{Material, Texture, Wrap};

/// A buffered reader that follows the bytes an OBJ or MTL parser consumes: it counts lines, so
/// a parse error can name its line, and it notes the face statements that tobj accepts
/// silently although they are wrong. The current line is shared so that a callback running
/// inside the parser can read it.
struct LineCounter<'a, R> {
    inner: R,
    scan: Scanner<'a>,
}

/// The lexer of [`LineCounter`].
struct Scanner<'a> {
    /// The 1-based line being parsed (0 before the first byte).
    line: &'a Cell<usize>,
    newlines: usize,
    /// Bytes of an unfinished line were consumed: the last line may lack its newline.
    partial: bool,
    lex: Lex,
    number: Number,
    found: Findings,
}

/// Where the lexer is in the current line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Lex {
    /// Only whitespace so far.
    LineStart,
    /// In the first word, which so far is...
    Keyword(Keyword),
    /// In the corners of an `f` statement.
    Face {
        corners: usize,
        /// 0: vertex index, 1: texture coordinate index, 2: normal index.
        field: u8,
        in_corner: bool,
    },
    /// The rest of a line that is not a face.
    Rest,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Keyword {
    F,
    V,
    Vt,
    Vn,
    Other,
}

/// What the lexer saw in an OBJ file.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Findings {
    /// The first face with fewer than 3 corners: (line, corners). tobj drops such faces.
    short_face: Option<(usize, usize)>,
    vt_lines: usize,
    vn_lines: usize,
    /// Some face gives a texture coordinate (normal) index. tobj ignores such indices
    /// unchecked when the file has no texture coordinates (normals).
    face_vt: bool,
    face_vn: bool,
    v_lines: usize,
    /// The largest positive face index of each kind (vertex, texture coordinate, normal),
    /// saturating. tobj multiplies indices unchecked, so a huge one wraps around to a wrong
    /// element instead of failing: the file is re-checked when one exceeds its element count.
    max_index: [u64; 3],
    /// Some face index is 0 (invalid: indices start at 1), or negative (relative; checked
    /// against the elements before its face on a re-check).
    zero_or_negative: bool,
}

impl Findings {
    /// Whether some face index may be out of range (see [`find_bad_face`]).
    fn suspect_indices(&self) -> bool {
        let counts = [self.v_lines, self.vt_lines, self.vn_lines];
        self.zero_or_negative || (0..3).any(|k| self.max_index[k] > counts[k] as u64)
    }
}

/// The number being lexed in a face corner's field.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Number {
    value: u64,
    negative: bool,
    digits: bool,
}

impl<'a, R> LineCounter<'a, R> {
    fn new(inner: R, line: &'a Cell<usize>) -> Self {
        line.set(0);
        let scan = Scanner {
            line,
            newlines: 0,
            partial: false,
            lex: Lex::LineStart,
            number: Number::default(),
            found: Findings::default(),
        };
        Self { inner, scan }
    }
}

impl Scanner<'_> {
    /// The end of field `field` (0: vertex, 1: texture coordinate, 2: normal) of a corner.
    fn end_field(&mut self, field: u8) {
        let n = std::mem::take(&mut self.number);
        if !n.digits || field > 2 {
            return;
        }
        if n.negative || n.value == 0 {
            self.found.zero_or_negative = true;
        } else {
            let max = &mut self.found.max_index[field as usize];
            *max = (*max).max(n.value);
        }
    }

    fn end_line(&mut self) {
        if let Lex::Face {
            field,
            in_corner: true,
            ..
        } = self.lex
        {
            self.end_field(field);
        }
        let corners = match self.lex {
            Lex::Keyword(Keyword::F) => Some(0),
            Lex::Face { corners, .. } => Some(corners),
            _ => None,
        };
        if let Some(n) = corners.filter(|&n| n < 3)
            && self.found.short_face.is_none()
        {
            self.found.short_face = Some((self.newlines + 1, n));
        }
        self.lex = Lex::LineStart;
    }

    fn scan(&mut self, bytes: &[u8]) {
        for &b in bytes {
            if b == b'\n' {
                self.end_line();
                self.newlines += 1;
                continue;
            }
            let space = matches!(b, b' ' | b'\t' | b'\r' | 0x0b | 0x0c);
            self.lex = match (self.lex, space) {
                (Lex::Rest, _) | (Lex::LineStart, true) => self.lex,
                (Lex::LineStart, false) => Lex::Keyword(match b {
                    b'f' => Keyword::F,
                    b'v' => Keyword::V,
                    _ => Keyword::Other,
                }),
                (Lex::Keyword(k), false) => Lex::Keyword(match (k, b) {
                    (Keyword::V, b't') => Keyword::Vt,
                    (Keyword::V, b'n') => Keyword::Vn,
                    _ => Keyword::Other,
                }),
                (Lex::Keyword(Keyword::F), true) => Lex::Face {
                    corners: 0,
                    field: 0,
                    in_corner: false,
                },
                (Lex::Keyword(k), true) => {
                    match k {
                        Keyword::Vt => self.found.vt_lines += 1,
                        Keyword::Vn => self.found.vn_lines += 1,
                        Keyword::V => self.found.v_lines += 1,
                        _ => {}
                    }
                    Lex::Rest
                }
                (
                    Lex::Face {
                        corners,
                        field,
                        in_corner,
                    },
                    true,
                ) => {
                    if in_corner {
                        self.end_field(field);
                    }
                    Lex::Face {
                        corners,
                        field: 0,
                        in_corner: false,
                    }
                }
                (
                    Lex::Face {
                        corners,
                        field,
                        in_corner,
                    },
                    false,
                ) => {
                    let (corners, field) = if in_corner {
                        (corners, field)
                    } else {
                        (corners + 1, 0)
                    };
                    let field = if b == b'/' {
                        self.end_field(field);
                        field.saturating_add(1)
                    } else {
                        match b {
                            b'-' => self.number.negative = true,
                            b'0'..=b'9' => {
                                let n = &mut self.number;
                                n.digits = true;
                                n.value =
                                    n.value.saturating_mul(10).saturating_add((b - b'0') as u64);
                            }
                            _ => {}
                        }
                        match field {
                            1 => self.found.face_vt = true,
                            2 => self.found.face_vn = true,
                            _ => {}
                        }
                        field
                    };
                    Lex::Face {
                        corners,
                        field,
                        in_corner: true,
                    }
                }
            };
        }
        if let Some(&last) = bytes.last() {
            self.partial = last != b'\n';
        }
        self.line.set(self.newlines + self.partial as usize);
    }

    /// What the lexer saw, once the parser has read everything.
    fn finish(&mut self) -> Findings {
        if self.partial {
            self.end_line();
        }
        self.found
    }
}

impl<R: BufRead> Read for LineCounter<'_, R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.scan.scan(&buf[..n]);
        Ok(n)
    }
}

impl<R: BufRead> BufRead for LineCounter<'_, R> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        self.inner.fill_buf()
    }

    fn consume(&mut self, amt: usize) {
        if let Ok(buf) = self.inner.fill_buf() {
            let amt = amt.min(buf.len());
            self.scan.scan(&buf[..amt]);
        }
        self.inner.consume(amt);
    }
}

/// The line a parser that reads line by line is on, once it has consumed it.
fn current_line(line: &Cell<usize>) -> usize {
    line.get().max(1)
}

/// A clearer wording of tobj's errors.
fn describe(e: tobj::LoadError) -> String {
    use tobj::LoadError as E;
    match e {
        E::FaceVertexOutOfBounds => {
            "face vertex index out of range (the face refers to a vertex that does not exist)"
                .into()
        }
        E::FaceTexCoordOutOfBounds => "face texture coordinate index out of range".into(),
        E::FaceNormalOutOfBounds => "face normal index out of range".into(),
        E::FaceColorOutOfBounds => "face vertex colour index out of range".into(),
        E::ReadError => "unreadable line (expected UTF-8 text)".into(),
        E::PositionParseError => "malformed vertex position (expected `v x y z`)".into(),
        E::NormalParseError => "malformed normal (expected `vn x y z`)".into(),
        E::TexcoordParseError => "malformed texture coordinate (expected `vt u v`)".into(),
        E::FaceParseError => "malformed face (expected `f v1[/vt1][/vn1] v2... v3...`)".into(),
        E::MaterialParseError => "malformed material statement".into(),
        other => other.to_string(),
    }
}

/// How tobj is asked to parse: faces as fans of triangles, one index per vertex (positions,
/// normals and texture coordinates share it, as a mesh needs), points and lines skipped.
const TOBJ_OPTIONS: tobj::LoadOptions = tobj::LoadOptions {
    triangulate: true,
    single_index: true,
    ignore_points: true,
    ignore_lines: true,
};

/// The error of a parser that panicked on the file.
fn parser_failed(path: &Path) -> LoadError {
    LoadError::Obj {
        at: Location::file(path),
        message: "malformed file (the OBJ/MTL parser failed on it)".into(),
    }
}

/// A parsed MTL library, or why it failed (with the line of its `mtllib` statement).
type MtlResult = Result<(Vec<tobj::Material>, PathBuf), (LoadError, usize)>;

/// What parsing an OBJ file gave, before any of it is judged.
struct Parsed {
    /// tobj's models, or what it reported.
    result: tobj::LoadResult,
    /// What the lexer saw that tobj lets through.
    found: Findings,
    /// The line the parser stopped on.
    line: usize,
    /// The MTL libraries tobj asked for, in order.
    libraries: Vec<MtlResult>,
}

/// Loads an OBJ file (and its MTL libraries and textures), applying `transform`.
pub fn load(
    path: &Path,
    transform: &Transform,
    textures: &mut TextureCache,
) -> Result<Model, LoadError> {
    let mut file = ModelFile::new(path, textures);
    let Parsed {
        result,
        found,
        line,
        libraries,
    } = parse(&file)?;
    // A failed material library is reported first (tobj carries on without it).
    let libraries = loaded_libraries(file.path, libraries)?;
    // Then the first problem in the file: what tobj reported, and what it lets through.
    let models = first_problem(&file, result, &found, line)?;
    let materials = materials(&mut file, libraries)?;
    let mut meshes = Vec::with_capacity(models.len());
    for model in models {
        meshes.extend(model_mesh(&file, model, transform, materials.len())?);
    }
    if meshes.is_empty() {
        return Err(LoadError::Obj {
            at: Location::file(path),
            message: "no triangles (expected `v` vertices and `f` faces)".into(),
        });
    }
    Ok(Model {
        meshes,
        materials,
        ..Model::default()
    })
}

/// What parsing an OBJ file holds at its peak, per byte of the file: tobj's vertex, index
/// and de-duplication tables and the mesh made from them, measured at 5 (a 68 MiB file of
/// two million triangles peaks at 349 MiB resident, the render included), with room for
/// tables that double as they grow (6 let a 14 MiB file abort under `ulimit -v`).
const PARSE_BYTES_PER_FILE_BYTE: u128 = 8;

/// Streams the file through tobj, counting lines and noting what tobj lets through, and
/// reads the MTL libraries it names as tobj asks for them.
fn parse(file: &ModelFile) -> Result<Parsed, LoadError> {
    let line = Cell::new(0);
    let mut input = file.open()?;
    // tobj grows its buffers infallibly (an abort, not an error, where memory runs out):
    // what it will hold is refused up front instead.
    let needed = u128::from(input.size()) * PARSE_BYTES_PER_FILE_BYTE;
    check_budget(
        "parsing the OBJ text (about 8 bytes per byte of the file)",
        needed,
    )
    .map_err(|e| memory_error(file.path, e))?;
    let mut reader = LineCounter::new(input.reader(), &line);
    // tobj asks for MTL libraries by name and keeps only their materials: keep which file
    // each came from (texture paths are relative to it) and any failure, with its line.
    let libraries: RefCell<Vec<MtlResult>> = RefCell::new(Vec::new());
    let result = guarded(
        || {
            tobj::load_obj_buf(&mut reader, &TOBJ_OPTIONS, |mtl| {
                let loaded = load_library(file, mtl, current_line(&line));
                let answer = tobj_answer(&loaded);
                libraries.borrow_mut().push(loaded);
                answer
            })
        },
        || parser_failed(file.path),
    );
    let found = reader.scan.finish();
    let line = current_line(&line);
    input.finish()?;
    // tobj's index arithmetic overflows on huge indices (a panic in checked builds): name the
    // face instead.
    let result = result.map_err(|panic| {
        found
            .suspect_indices()
            .then(|| find_bad_face(file))
            .flatten()
            .map_or(panic, |(line, message)| LoadError::Obj {
                at: Location::line(file.path, line),
                message,
            })
    })?;
    Ok(Parsed {
        result,
        found,
        line,
        libraries: libraries.into_inner(),
    })
}

/// The MTL library `mtl` that line `line` of the OBJ names, read and parsed.
fn load_library(file: &ModelFile, mtl: &Path, line: usize) -> MtlResult {
    let at = Location::line(file.path, line);
    mtl.to_str()
        .ok_or_else(|| LoadError::Obj {
            at: at.clone(),
            message: "the MTL file name is not UTF-8".into(),
        })
        .and_then(|name| file.reference(Path::new(""), name, &at))
        .and_then(|full| load_mtl(&full, file.options()))
        .map_err(|e| (e, line))
}

/// What tobj is told of a library it asked for: its materials by name, or that it failed
/// (the real error is kept for [`loaded_libraries`]).
fn tobj_answer(loaded: &MtlResult) -> tobj::MTLLoadResult {
    match loaded {
        Ok((mats, _)) => {
            let map = mats
                .iter()
                .enumerate()
                .map(|(i, m)| (m.name.clone(), i))
                .collect();
            Ok((mats.clone(), map))
        }
        Err(_) => Err(tobj::LoadError::OpenFileFailed),
    }
}

/// The libraries with the file each came from, or the first failure, named as the library
/// referenced from its `mtllib` line (a path outside the model's folder is said as such).
fn loaded_libraries(
    path: &Path,
    libraries: Vec<MtlResult>,
) -> Result<Vec<(Vec<tobj::Material>, PathBuf)>, LoadError> {
    let mut loaded = Vec::new();
    for lib in libraries {
        match lib {
            Ok(lib) => loaded.push(lib),
            Err((e @ LoadError::OutsidePath { .. }, _)) => return Err(e),
            Err((e, line)) => {
                return Err(e.referenced(Location::line(path, line), "material library"));
            }
        }
    }
    Ok(loaded)
}

/// tobj's models, or the problem on the earliest line among those tobj reported and those it
/// lets through (a short face it drops, indices it does not check).
fn first_problem(
    file: &ModelFile,
    result: tobj::LoadResult,
    found: &Findings,
    line: usize,
) -> Result<Vec<tobj::Model>, LoadError> {
    let mut problems = Vec::new();
    if let Some((line, corners)) = found.short_face {
        problems.push((
            line,
            format!(
                "face with {corners} corner{}: a face needs at least 3 vertex indices \
                 (`f v1 v2 v3 ...`; truncated line?)",
                if corners == 1 { "" } else { "s" }
            ),
        ));
    }
    let models = match result {
        // tobj checks face indices when an object ends: find the face itself.
        Err(
            e @ (tobj::LoadError::FaceVertexOutOfBounds
            | tobj::LoadError::FaceTexCoordOutOfBounds
            | tobj::LoadError::FaceNormalOutOfBounds),
        ) => {
            problems.push(find_bad_face(file).unwrap_or_else(|| (line, describe(e))));
            None
        }
        Err(e) => {
            problems.push((line, describe(e)));
            None
        }
        Ok((models, _)) => {
            // tobj ignores texture and normal indices unchecked when the file has none.
            if (found.face_vt && found.vt_lines == 0)
                || (found.face_vn && found.vn_lines == 0)
                || found.suspect_indices()
            {
                problems.extend(find_bad_face(file));
            }
            Some(models)
        }
    };
    if let Some((line, message)) = problems.into_iter().min_by_key(|&(line, _)| line) {
        return Err(LoadError::Obj {
            at: Location::line(file.path, line),
            message,
        });
    }
    Ok(models.expect("a failed parse reported a problem"))
}

/// The libraries' materials with their names, numbered across libraries in load order, as
/// tobj numbers them for the meshes.
fn materials(
    file: &mut ModelFile,
    libraries: Vec<(Vec<tobj::Material>, PathBuf)>,
) -> Result<Vec<(String, Material)>, LoadError> {
    let mut materials = Vec::new();
    for (mats, mtl_path) in libraries {
        // Textures resolve relative to the MTL file, and must stay in the OBJ's folder.
        let mtl_dir = mtl_path.parent().unwrap_or(Path::new(""));
        let mtl_dir = mtl_dir.strip_prefix(&file.folder).unwrap_or(mtl_dir);
        for m in mats {
            let material = convert_material(file, &m, &mtl_path, mtl_dir)?;
            materials.push((m.name.clone(), material));
        }
    }
    Ok(materials)
}

/// One tobj model (an OBJ object or group, with one material) as a mesh in world space, or
/// `None` when no triangle with area is left of it.
fn model_mesh(
    file: &ModelFile,
    model: tobj::Model,
    transform: &Transform,
    material_count: usize,
) -> Result<Option<ModelMesh>, LoadError> {
    let name = model.name;
    let tobj::Mesh {
        positions,
        normals,
        texcoords,
        indices,
        material_id,
        ..
    } = model.mesh;
    let vertices = positions.len() / 3;
    let triangles = indices.len() / 3;
    if vertices == 0 || triangles == 0 {
        return Ok(None);
    }
    // Transformed in tobj's buffers, which are then copied into the mesh's and freed.
    let mut positions = positions;
    if !transform.is_identity() {
        for c in positions.chunks_exact_mut(3) {
            c.copy_from_slice(&transform.point([c[0], c[1], c[2]]));
        }
    }
    let positions = into_arrays::<f32, 3>(file.path, positions, 1)?;
    let mut triangles = into_arrays::<u32, 3>(file.path, indices, 1)?;
    drop_degenerate_and_repeated(&mut triangles);
    if triangles.is_empty() {
        return Ok(None);
    }
    keep_winding(&mut triangles, transform);
    // Only complete per-vertex attributes are kept (some faces may lack them).
    let normals = (normals.len() == vertices * 3)
        .then(|| {
            let mut normals = normals;
            if !transform.is_identity() {
                for c in normals.chunks_exact_mut(3) {
                    c.copy_from_slice(&transform.normal([c[0], c[1], c[2]]));
                }
            }
            into_arrays::<f32, 3>(file.path, normals, 0)
        })
        .transpose()?;
    let uvs = (texcoords.len() == vertices * 2)
        .then(|| into_arrays::<f32, 2>(file.path, texcoords, 0))
        .transpose()?;
    let what = if name.is_empty() {
        "mesh".to_string()
    } else {
        format!("object {name:?}")
    };
    let buffers = MeshBuffers {
        positions,
        triangles,
        normals,
        uvs,
        tangents: None,
    };
    Ok(Some(ModelMesh {
        mesh: file.mesh(&what, buffers)?,
        material: material_id.filter(|&m| m < material_count),
    }))
}

/// A flat buffer (`N` values per element) as one array per element, with room for `spare`
/// more elements (TriangleMesh pads positions and indices by one for Embree). The source is
/// freed as soon as it is copied, so at most one buffer is held twice at a time.
///
/// Reusing tobj's allocation instead of copying would need `unsafe` (std has no safe
/// `Vec<T>` to `Vec<[T; N]>` conversion), which the crate denies outside `embree`; measured
/// on a 1M-triangle OBJ it would not lower the peak either, which comes from tobj's parse.
/// Allocated fallibly: memory that cannot be had is the file's resource-limit error.
fn into_arrays<T: Copy, const N: usize>(
    path: &Path,
    v: Vec<T>,
    spare: usize,
) -> Result<Vec<[T; N]>, LoadError> {
    let mut out = buffer(path, v.len() / N + spare, "a mesh's vertex data")?;
    out.extend(v.chunks_exact(N).map(|c| std::array::from_fn(|i| c[i])));
    Ok(out)
}

/// Removes triangles with a repeated corner (no area) and repeats of a triangle (the same
/// corners in the same winding): coincident triangles add nothing to the image, but a BVH
/// cannot separate them, so every ray near them would test them all. A fan over a face that
/// repeats its corners (`f 1 2 3 1 2 3 ...`) is made of nothing else. Linear (one hash set).
fn drop_degenerate_and_repeated(t: &mut Vec<[u32; 3]>) {
    let mut seen = std::collections::HashSet::with_capacity(t.len().min(1 << 20));
    t.retain(|&[a, b, c]| {
        if a == b || b == c || a == c {
            return false;
        }
        // The rotation starting at the smallest index names the triangle and its winding.
        let key = if a < b && a < c {
            [a, b, c]
        } else if b < c {
            [b, c, a]
        } else {
            [c, a, b]
        };
        seen.insert(key)
    });
}

/// The first face of an OBJ file whose vertex, texture or normal index is out of range, and
/// what is wrong with it. Indices are 1-based; negative ones count back from the latest element.
fn find_bad_face(file: &ModelFile) -> Option<(usize, String)> {
    let text = file.read().ok()?;
    let text = String::from_utf8_lossy(&text);
    let totals = text.lines().fold([0usize; 3], |mut t, l| {
        match l.split_whitespace().next() {
            Some("v") => t[0] += 1,
            Some("vt") => t[1] += 1,
            Some("vn") => t[2] += 1,
            _ => {}
        }
        t
    });
    let names = ["vertex", "texture coordinate", "normal"];
    let plurals = ["vertices", "texture coordinates", "normals"];
    let mut seen = [0usize; 3];
    for (i, l) in text.lines().enumerate() {
        let mut words = l.split_whitespace();
        match words.next() {
            Some("v") => seen[0] += 1,
            Some("vt") => seen[1] += 1,
            Some("vn") => seen[2] += 1,
            Some("f") => {
                for corner in words {
                    for (k, idx) in corner.split('/').enumerate().take(3) {
                        if idx.is_empty() {
                            continue;
                        }
                        let Ok(idx) = idx.parse::<i64>() else {
                            return Some((
                                i + 1,
                                format!(
                                    "face {} index {:?} is not a valid index (expected a \
                                     whole number, 1-based; negative counts back)",
                                    names[k], idx
                                ),
                            ));
                        };
                        let ok = if idx > 0 {
                            idx as u64 <= totals[k] as u64
                        } else {
                            idx != 0 && idx.unsigned_abs() <= seen[k] as u64
                        };
                        if !ok {
                            return Some((
                                i + 1,
                                format!(
                                    "face {} index {idx} is out of range: the file has {} {} \
                                     (indices start at 1; negative ones count back)",
                                    names[k],
                                    totals[k],
                                    if totals[k] == 1 { names[k] } else { plurals[k] }
                                ),
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    None
}

/// Parses an MTL file, naming its line on errors. Colour statements (`Ka`, `Kd`, `Ks`, `Ke`)
/// with a single value mean grey, as the MTL format allows; they are expanded to three values
/// first (tobj expects three).
fn load_mtl(
    path: &Path,
    options: &LoadOptions,
) -> Result<(Vec<tobj::Material>, PathBuf), LoadError> {
    let bytes = input::read(path, options)?;
    let text = String::from_utf8(bytes).map_err(|e| {
        let line = e.as_bytes()[..e.utf8_error().valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1;
        LoadError::Obj {
            at: Location::line(path, line),
            message: "unreadable line (expected UTF-8 text)".into(),
        }
    })?;
    let mut fixed = String::with_capacity(text.len() + 64);
    for (i, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        if let Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) = words.next() {
            let values: Vec<&str> = words.collect();
            match values.len() {
                1 => {
                    let v = values[0];
                    fixed.push_str(&format!("{key} {v} {v} {v}\n"));
                    continue;
                }
                3 => {}
                n => {
                    return Err(LoadError::Obj {
                        at: Location::line(path, i + 1),
                        message: format!(
                            "`{key}` has {n} values (expected r g b, or one grey value)"
                        ),
                    });
                }
            }
        }
        fixed.push_str(line);
        fixed.push('\n');
    }
    let line = Cell::new(0);
    let mut reader = LineCounter::new(std::io::Cursor::new(fixed.as_bytes()), &line);
    let result = guarded(|| tobj::load_mtl_buf(&mut reader), || parser_failed(path))?;
    match result {
        Ok((mats, _)) => Ok((mats, path.to_path_buf())),
        Err(e) => Err(LoadError::Obj {
            at: Location::line(path, current_line(&line)),
            message: describe(e),
        }),
    }
}

fn color(c: Option<[f32; 3]>, default: Vec3) -> Vec3 {
    c.map(Vec3::from)
        .filter(|v| v.is_finite())
        .map_or(default, |v| v.max(Vec3::ZERO))
}

/// `mtl_dir`: the MTL's folder relative to the OBJ's, where its texture paths start.
fn convert_material(
    file: &mut ModelFile,
    m: &tobj::Material,
    mtl_path: &Path,
    mtl_dir: &Path,
) -> Result<Material, LoadError> {
    let kd = m.diffuse.map(Vec3::from).filter(|v| v.is_finite());
    let diffuse = match &m.diffuse_texture {
        Some(statement) => {
            let name = texture_file(statement);
            let at = Location::file(mtl_path).with_key(format!("{}.map_Kd", m.name));
            let image = file.texture((mtl_dir, name), true, Wrap::Repeat, at)?;
            Texture::Image {
                image,
                tint: kd.map_or(Vec3::ONE, |v| v.max(Vec3::ZERO)),
            }
        }
        None => Texture::Constant(color(m.diffuse, Vec3::splat(0.8))),
    };
    let specular = color(m.specular, Vec3::ZERO);
    // `Ns` is a Phong exponent; the GGX roughness of the same highlight width follows Walter et
    // al.'s Beckmann correspondence, alpha = sqrt(2 / (Ns + 2)), roughness = sqrt(alpha).
    let roughness = m
        .shininess
        .filter(|s| s.is_finite() && *s >= 0.0)
        .map_or(1.0, |s| (2.0 / (s + 2.0)).sqrt().sqrt().clamp(0.0, 1.0));
    // Ray-traced reflection (`illum` 3, 5 or 7) makes the surface a metal of colour `Ks` that
    // strong.
    let metallic = match m.illumination_model {
        Some(3 | 5 | 7) => specular.max_element().clamp(0.0, 1.0),
        _ => 0.0,
    };
    // `Ke`: emitted radiance. Negative components mean none, as for the other colours; a
    // value the renderer would refuse is an error naming the statement.
    let emission = match m.emissive.map(Vec3::from) {
        None => Vec3::ZERO,
        Some(e) if !(e.is_finite() && e.max_element() <= MAX_MATERIAL_VALUE) => {
            return Err(LoadError::Obj {
                at: Location::file(mtl_path).with_key(format!("{}.Ke", m.name)),
                message: format!(
                    "emission {} is out of range: each component must be finite and at most 1e6",
                    short_vec(e)
                ),
            });
        }
        Some(e) => e.max(Vec3::ZERO),
    };
    let base_color = match diffuse {
        Texture::Constant(kd) if metallic > 0.0 => Texture::Constant(kd.lerp(specular, metallic)),
        other => other,
    };
    Ok(Material {
        base_color,
        metallic,
        roughness,
        emission,
        emission_texture: None,
        // A dielectric with glTF's default index (the 4% reflection MTL's `Ks` stands for).
        ior: 1.5,
        ..Material::diffuse(Vec3::ZERO)
    })
}

/// The file name in a `map_Kd` statement: options such as `-s 1 1 1` come first, the file last.
fn texture_file(statement: &str) -> &str {
    let s = statement.trim();
    if s.starts_with('-') {
        s.rsplit(char::is_whitespace).next().unwrap_or(s)
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parses `text` through a LineCounter: (parse failed, current line, findings).
    fn parse(text: &str) -> (bool, usize, Findings) {
        let line = Cell::new(0);
        let mut r = LineCounter::new(std::io::Cursor::new(text.as_bytes()), &line);
        let opts = tobj::LoadOptions {
            triangulate: true,
            single_index: true,
            ignore_points: true,
            ignore_lines: true,
        };
        let res = tobj::load_obj_buf(&mut r, &opts, |_| Err(tobj::LoadError::OpenFileFailed));
        (res.is_err(), current_line(&line), r.scan.finish())
    }

    #[test]
    fn the_line_counter_names_the_failing_line() {
        // tobj reports out-of-range faces when it finishes the object, at the end of the file.
        let (failed, _, _) = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\nf 1 2 3\n");
        assert!(failed);
        assert_eq!(parse("v 0 0 0\nv x 0 0\n").1, 2);
        // A last line without its newline is still the line it is.
        assert_eq!(parse("v 0 0 0\nv x 0 0").1, 2);
        assert_eq!(parse("v x 0 0").1, 1);
        assert_eq!(parse("v 0 0 0\r\nv 0 0 0\r\nv x").1, 3);
    }

    #[test]
    fn the_scanner_finds_short_faces_and_attribute_indices() {
        let (failed, _, found) = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n  f\t1 2\r\nf 1\n");
        assert!(!failed, "tobj accepts short faces");
        assert_eq!(found.short_face, Some((5, 2)));
        assert_eq!(parse("v 0 0 0\nf 1 2 3\nf").2.short_face, Some((3, 0)));
        assert_eq!(parse("v 0 0 0\nf 1 2 3\nf 1 1").2.short_face, Some((3, 2)));
        let found = parse("v 0 0 0\nfoo 1\nf 1 1 1\nvt 0 0\nvtx 1\n").2;
        assert_eq!(found.short_face, None);
        assert_eq!((found.vt_lines, found.vn_lines), (1, 0));
        assert!(!found.face_vt && !found.face_vn);
        let found = parse("v 0 0 0\nf 1/5 1 1\n").2;
        assert!(found.face_vt && !found.face_vn);
        let found = parse("v 0 0 0\nvn 0 0 1\nf 1//1 1//1 1//1\n").2;
        assert!(!found.face_vt && found.face_vn);
        assert_eq!(found.vn_lines, 1);
    }

    #[test]
    fn flat_buffers_become_arrays_with_spare_room() {
        let mut v: Vec<f32> = Vec::with_capacity(1000);
        v.extend((0..300).map(|i| i as f32));
        let a: Vec<[f32; 3]> = into_arrays(Path::new("t.obj"), v, 1).unwrap();
        assert_eq!(a.len(), 100);
        assert_eq!(
            a.capacity(),
            101,
            "one spare element for TriangleMesh's padding"
        );
        assert_eq!(a[99], [297.0, 298.0, 299.0]);
        let b: Vec<[u32; 2]> = into_arrays(Path::new("t.obj"), vec![1, 2, 3, 4], 0).unwrap();
        assert_eq!((b.as_slice(), b.capacity()), (&[[1, 2], [3, 4]][..], 2));
    }

    #[test]
    fn texture_options_are_skipped() {
        assert_eq!(texture_file("wood.png"), "wood.png");
        assert_eq!(texture_file("-s 2 2 1 wood.png"), "wood.png");
    }
}
