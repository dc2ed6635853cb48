//! Wavefront OBJ meshes with MTL materials and textures, via `tobj`.
//!
//! Faces are triangulated (fans); each OBJ object/group and material becomes one mesh with one
//! index per vertex. MTL: `Kd` diffuse colour, `map_Kd` diffuse texture (sRGB, multiplied by
//! `Kd` when both are given), `Ks` specular colour, `Ns` shininess; `illum` 3, 5 or 7 (ray-traced
//! reflection) makes the surface a mirror of strength `max(Ks)`.

use std::cell::{Cell, RefCell};
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use glam::Vec3;

use super::error::{LoadError, Location};
use super::model::{Model, ModelMesh, Transform, mesh};
use super::texture::TextureCache;
use crate::shade::{Material, Texture, Wrap};

/// A buffered reader that counts the lines consumed, so a parse error can name its line.
/// The count is shared so that a callback running inside the parser can read it.
struct LineCounter<'a, R> {
    inner: R,
    newlines: &'a Cell<usize>,
}

impl<R: BufRead> Read for LineCounter<'_, R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        let lines = buf[..n].iter().filter(|&&b| b == b'\n').count();
        self.newlines.set(self.newlines.get() + lines);
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
            let lines = buf[..amt].iter().filter(|&&b| b == b'\n').count();
            self.newlines.set(self.newlines.get() + lines);
        }
        self.inner.consume(amt);
    }
}

/// The line a parser that reads line by line is on, once it has consumed it.
fn current_line(newlines: &Cell<usize>) -> usize {
    newlines.get().max(1)
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

fn open<'a>(
    path: &Path,
    newlines: &'a Cell<usize>,
) -> Result<LineCounter<'a, BufReader<File>>, LoadError> {
    let file = File::open(path).map_err(|e| LoadError::io(path, e))?;
    if file.metadata().is_ok_and(|m| m.is_dir()) {
        let e = std::io::Error::new(std::io::ErrorKind::IsADirectory, "is a directory");
        return Err(LoadError::io(path, e));
    }
    Ok(LineCounter {
        inner: BufReader::with_capacity(1 << 16, file),
        newlines,
    })
}

/// Runs a third-party parser, turning a panic inside it into an error.
fn guarded<T>(path: &Path, f: impl FnOnce() -> T) -> Result<T, LoadError> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|_| LoadError::Obj {
        at: Location::file(path),
        message: "malformed file (the OBJ/MTL parser failed on it)".into(),
    })
}

/// A parsed MTL library, or why it failed (with the line of its `mtllib` statement).
type MtlResult = Result<(Vec<tobj::Material>, PathBuf), (LoadError, usize)>;

/// Loads an OBJ file (and its MTL libraries and textures), applying `transform`.
pub fn load(
    path: &Path,
    transform: &Transform,
    textures: &mut TextureCache,
) -> Result<Model, LoadError> {
    let newlines = Cell::new(0);
    let mut reader = open(path, &newlines)?;
    let dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
    // MTL libraries: tobj asks for them by name; remember which file each material came from
    // (texture paths are relative to it) and any failure, with its line.
    let libraries: RefCell<Vec<MtlResult>> = RefCell::new(Vec::new());
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let result = guarded(path, || {
        tobj::load_obj_buf(&mut reader, &options, |mtl| {
            let full = dir.join(mtl);
            let loaded = load_mtl(&full).map_err(|e| (e, current_line(&newlines)));
            let ret = match &loaded {
                Ok((mats, _)) => {
                    let map = mats
                        .iter()
                        .enumerate()
                        .map(|(i, m)| (m.name.clone(), i))
                        .collect();
                    Ok((mats.clone(), map))
                }
                Err(_) => Err(tobj::LoadError::OpenFileFailed),
            };
            libraries.borrow_mut().push(loaded);
            ret
        })
    })?;
    let line = current_line(&newlines);
    drop(reader);
    // A failed material library is reported first (tobj carries on without it).
    let mut loaded = Vec::new();
    for lib in libraries.into_inner() {
        match lib {
            Ok(lib) => loaded.push(lib),
            Err((e, line)) => {
                return Err(e.referenced(Location::line(path, line), "material library"));
            }
        }
    }
    let (models, _) = result.map_err(|e| match e {
        // tobj checks face indices when an object ends: find the face itself.
        tobj::LoadError::FaceVertexOutOfBounds
        | tobj::LoadError::FaceTexCoordOutOfBounds
        | tobj::LoadError::FaceNormalOutOfBounds => match find_bad_face(path) {
            Some((line, message)) => LoadError::Obj {
                at: Location::line(path, line),
                message,
            },
            None => LoadError::Obj {
                at: Location::line(path, line),
                message: describe(e),
            },
        },
        e => LoadError::Obj {
            at: Location::line(path, line),
            message: describe(e),
        },
    })?;

    // tobj numbers materials across libraries in load order; so do we.
    let mut materials = Vec::new();
    for (mats, mtl_path) in loaded {
        let mtl_dir = mtl_path.parent().unwrap_or(Path::new("")).to_path_buf();
        for m in mats {
            let material = convert_material(&m, &mtl_path, &mtl_dir, textures)?;
            materials.push((m.name.clone(), material));
        }
    }

    let mut meshes = Vec::with_capacity(models.len());
    for model in models {
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
            continue;
        }
        // One spare element each: TriangleMesh pads its buffers for Embree without reallocating.
        let mut p = Vec::with_capacity(vertices + 1);
        p.extend(
            positions
                .chunks_exact(3)
                .map(|c| transform.point([c[0], c[1], c[2]])),
        );
        drop(positions);
        let mut t = Vec::with_capacity(triangles + 1);
        if transform.mirrors {
            t.extend(indices.chunks_exact(3).map(|c| [c[0], c[2], c[1]]));
        } else {
            t.extend(indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        }
        drop(indices);
        // Only complete per-vertex attributes are kept (some faces may lack them).
        let n = (normals.len() == vertices * 3).then(|| {
            normals
                .chunks_exact(3)
                .map(|c| transform.normal([c[0], c[1], c[2]]))
                .collect()
        });
        drop(normals);
        let uv = (texcoords.len() == vertices * 2)
            .then(|| texcoords.chunks_exact(2).map(|c| [c[0], c[1]]).collect());
        drop(texcoords);
        let what = if name.is_empty() {
            "mesh".to_string()
        } else {
            format!("object {name:?}")
        };
        let mesh = mesh(path, &what, p, t, n, uv)?;
        meshes.push(ModelMesh {
            mesh,
            material: material_id.filter(|&m| m < materials.len()),
        });
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
        camera: None,
    })
}

/// The first face of an OBJ file whose vertex, texture or normal index is out of range, and
/// what is wrong with it. Indices are 1-based; negative ones count back from the latest element.
fn find_bad_face(path: &Path) -> Option<(usize, String)> {
    let text = std::fs::read(path).ok()?;
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
                            continue;
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
fn load_mtl(path: &Path) -> Result<(Vec<tobj::Material>, PathBuf), LoadError> {
    let bytes = std::fs::read(path).map_err(|e| LoadError::io(path, e))?;
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
    let newlines = Cell::new(0);
    let mut reader = LineCounter {
        inner: std::io::Cursor::new(fixed.as_bytes()),
        newlines: &newlines,
    };
    let result = guarded(path, || tobj::load_mtl_buf(&mut reader))?;
    match result {
        Ok((mats, _)) => Ok((mats, path.to_path_buf())),
        Err(e) => Err(LoadError::Obj {
            at: Location::line(path, current_line(&newlines)),
            message: describe(e),
        }),
    }
}

fn color(c: Option<[f32; 3]>, default: Vec3) -> Vec3 {
    c.map(Vec3::from)
        .filter(|v| v.is_finite())
        .map_or(default, |v| v.max(Vec3::ZERO))
}

fn convert_material(
    m: &tobj::Material,
    mtl_path: &Path,
    mtl_dir: &Path,
    textures: &mut TextureCache,
) -> Result<Material, LoadError> {
    let kd = m.diffuse.map(Vec3::from).filter(|v| v.is_finite());
    let diffuse = match &m.diffuse_texture {
        Some(file) => {
            let file = texture_file(file);
            let tex_path = mtl_dir.join(file);
            let image = textures.file(&tex_path, true, Wrap::Repeat).map_err(|e| {
                e.referenced(
                    Location::file(mtl_path).with_key(format!("{}.map_Kd", m.name)),
                    "texture",
                )
            })?;
            Texture::Image {
                image,
                tint: kd.map_or(Vec3::ONE, |v| v.max(Vec3::ZERO)),
            }
        }
        None => Texture::Constant(color(m.diffuse, Vec3::splat(0.8))),
    };
    let specular = color(m.specular, Vec3::ZERO);
    let shininess = m
        .shininess
        .filter(|s| s.is_finite() && *s >= 1.0)
        .unwrap_or(32.0);
    let mirror = match m.illumination_model {
        Some(3 | 5 | 7) => specular.max_element().clamp(0.0, 1.0),
        _ => 0.0,
    };
    Ok(Material {
        diffuse,
        specular,
        shininess,
        mirror,
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

    #[test]
    fn the_line_counter_names_the_failing_line() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\nf 1 2 3\n";
        let count = Cell::new(0);
        let mut r = LineCounter {
            inner: std::io::Cursor::new(text.as_bytes()),
            newlines: &count,
        };
        let opts = tobj::LoadOptions {
            triangulate: true,
            single_index: true,
            ..Default::default()
        };
        let res = tobj::load_obj_buf(&mut r, &opts, |_| Err(tobj::LoadError::OpenFileFailed));
        // tobj reports out-of-range faces when it finishes the object, at the end of the file.
        assert!(res.is_err());
        let text = "v 0 0 0\nv x 0 0\n";
        let count = Cell::new(0);
        let mut r = LineCounter {
            inner: std::io::Cursor::new(text.as_bytes()),
            newlines: &count,
        };
        assert!(
            tobj::load_obj_buf(&mut r, &opts, |_| Err(tobj::LoadError::OpenFileFailed)).is_err()
        );
        assert_eq!(current_line(&count), 2);
    }

    #[test]
    fn texture_options_are_skipped() {
        assert_eq!(texture_file("wood.png"), "wood.png");
        assert_eq!(texture_file("-s 2 2 1 wood.png"), "wood.png");
    }
}
