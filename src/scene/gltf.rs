//! glTF 2.0 models (`.gltf` with external or embedded buffers, and binary `.glb`), via `gltf`.
//!
//! The default scene's node tree is walked with each node's transform; every triangle primitive
//! becomes one mesh with positions, normals (inverse-transpose transformed) and the UV set of
//! its base-colour texture. Materials: base-colour factor and texture (sRGB), metallic and
//! roughness (factors and texture), transmission and IOR become dofray's glTF material (see
//! `docs/scene-format.md`). The first perspective camera met in the tree is returned too, and
//! the KHR_lights_punctual lights of the nodes (converted from photometric to radiometric
//! units). An extension in `extensionsRequired` that is not in [`SUPPORTED_EXTENSIONS`] is an
//! error; everything else the file uses and dofray ignores is named in one warning.
//! Accessors are checked before they are read, and a panic inside the parser becomes an error.

use std::collections::{HashMap, HashSet};
use std::path::Path;
use std::sync::Arc;

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::mesh::Mode;
use ::gltf::texture::WrappingMode;
use glam::{Affine3A, Mat4, Vec3};

use super::error::{LoadError, Location, shown};
use super::input::{self, LoadOptions};
use super::mesh_input::{MeshBuffers, ModelFile, buffer, guarded, keep_winding};
use super::model::{CameraDof, Model, ModelCamera, ModelMesh, Transform, short_number, short_vec};
use super::texture::{TextureCache, decode};
use super::{MAX_LIGHT_VALUE, MAX_MATERIAL_VALUE};
use crate::camera::check_vfov;
use crate::shade::{
    Alpha, AlphaMode, ImageTexture, LUMENS_PER_WATT, Light, Material, MaterialMaps, NormalMap,
    Texture, Wrap,
};

/// The glTF extensions dofray implements: a file may require these (`extensionsRequired`);
/// requiring any other is an error, and using any other is named in the file's warning.
/// Keep this the one list (loaders of new extensions append here).
pub const SUPPORTED_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_transmission",
    "KHR_materials_ior",
    "KHR_materials_volume",
];

fn gltf_error(path: &Path, message: impl Into<String>) -> LoadError {
    LoadError::Gltf {
        at: Location::file(path),
        message: message.into(),
    }
}

/// Decodes standard base64 (padding optional, whitespace ignored).
pub fn base64_decode(text: &str) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(text.len() / 4 * 3);
    let mut acc = 0u32;
    let mut bits = 0;
    let mut padding = 0;
    for c in text.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => {
                padding += 1;
                continue;
            }
            b' ' | b'\n' | b'\r' | b'\t' => continue,
            _ => return None,
        };
        if padding > 0 {
            return None;
        }
        acc = (acc << 6) | v as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    (padding <= 2).then_some(out)
}

/// Decodes `%XX` escapes of a relative URI.
fn percent_decode(uri: &str) -> Vec<u8> {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            let hex = std::str::from_utf8(&b[i + 1..i + 3])
                .ok()
                .and_then(|h| u8::from_str_radix(h, 16).ok());
            if let Some(v) = hex {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    out
}

/// The file name a relative URI spells (percent escapes decoded); `what` names the URI's
/// user in the error.
fn uri_file_name(path: &Path, uri: &str, what: &str) -> Result<String, LoadError> {
    String::from_utf8(percent_decode(uri))
        .map_err(|_| gltf_error(path, format!("{what}: URI {uri:?} is not UTF-8")))
}

/// The bytes a URI names: a base64 `data:` URI, or a file relative to the model (by the path
/// policy of [`input::reference`]).
fn read_uri(file: &ModelFile, uri: &str, what: &'static str) -> Result<Vec<u8>, LoadError> {
    let path = file.path;
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, data) = rest.split_once(";base64,").ok_or_else(|| {
            gltf_error(path, format!("{what}: only base64 data URIs are supported"))
        })?;
        return base64_decode(data)
            .ok_or_else(|| gltf_error(path, format!("{what}: malformed base64 in a data URI")));
    }
    let scheme = uri.find(':').filter(|&i| {
        i > 1
            && uri[..i]
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
    });
    if scheme.is_some() {
        return Err(gltf_error(
            path,
            format!("{what}: unsupported URI {uri:?} (expected a relative file or a data URI)"),
        ));
    }
    let name = uri_file_name(path, uri, what)?;
    let at = Location::file(path);
    let referenced = file.reference(Path::new(""), &name, &at)?;
    input::read(&referenced, file.options()).map_err(|e| e.referenced(at, what))
}

/// Checks that reading `accessor` cannot go out of its buffer or hit a type the reader does
/// not expect.
fn check_accessor(
    path: &Path,
    buffers: &[Vec<u8>],
    accessor: &::gltf::Accessor,
    what: &str,
    dims: Dimensions,
    types: &[DataType],
) -> Result<(), LoadError> {
    let fail = |m: String| gltf_error(path, format!("accessor {} ({what}): {m}", accessor.index()));
    if accessor.dimensions() != dims || !types.contains(&accessor.data_type()) {
        return Err(fail(format!(
            "expected {dims:?} of {types:?}, got {:?} of {:?}",
            accessor.dimensions(),
            accessor.data_type()
        )));
    }
    if accessor.sparse().is_some() {
        return Err(fail("sparse accessors are not supported".into()));
    }
    let count = accessor.count();
    if count == 0 {
        return Err(fail("no elements".into()));
    }
    let view = accessor
        .view()
        .ok_or_else(|| fail("no buffer view (expected the data in a buffer)".into()))?;
    let size = accessor.size();
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(fail(format!("byte stride {stride} < element size {size}")));
    }
    let data = buffers
        .get(view.buffer().index())
        .ok_or_else(|| fail("missing buffer".into()))?;
    let view_end = view.offset().checked_add(view.length());
    let need = (count - 1)
        .checked_mul(stride)
        .and_then(|n| n.checked_add(size))
        .and_then(|n| n.checked_add(accessor.offset()));
    match (view_end, need) {
        (Some(end), Some(need)) if end <= data.len() && need <= view.length() => Ok(()),
        _ => Err(fail(format!(
            "{count} elements do not fit in buffer view {} (truncated file?)",
            view.index()
        ))),
    }
}

/// A binary glTF (starting with `glTF`) must be as long as its header and chunks declare:
/// a shorter one is a truncated file, said so with both sizes.
fn check_glb_length(path: &Path, bytes: &[u8]) -> Result<(), LoadError> {
    if !bytes.starts_with(b"glTF") {
        return Ok(());
    }
    let word = |at: usize| {
        bytes
            .get(at..at + 4)
            .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]) as u64)
    };
    let Some(declared) = word(8) else {
        return Err(gltf_error(
            path,
            format!(
                "truncated GLB file: it has {} bytes, less than the 12-byte GLB header",
                bytes.len()
            ),
        ));
    };
    // (The glTF parser subtracts the header from this length: below 12 it underflows.)
    if declared < 12 {
        return Err(gltf_error(
            path,
            format!(
                "corrupt GLB file: its header declares a length of {declared} bytes, less than \
                 the 12-byte header itself"
            ),
        ));
    }
    let size = bytes.len() as u64;
    if size < declared {
        return Err(gltf_error(
            path,
            format!(
                "truncated GLB file: its header declares {declared} bytes, but the file has \
                 {size} ({} missing)",
                declared - size
            ),
        ));
    }
    // Each chunk: length, type, data; the chunks must fit in the declared length.
    let mut at = 12u64;
    let mut index = 0;
    while at < declared {
        let (Some(length), Some(kind)) = (word(at as usize), word(at as usize + 4)) else {
            break;
        };
        let end = at + 8 + length;
        if at + 8 > declared || end > declared {
            let name = match kind {
                0x4E4F_534A => "JSON",
                0x004E_4942 => "BIN",
                _ => "unknown",
            };
            return Err(gltf_error(
                path,
                format!(
                    "truncated or corrupt GLB file: chunk {index} ({name}) declares {length} \
                     bytes at offset {}, past the {declared} bytes the header declares",
                    at + 8
                ),
            ));
        }
        at = end;
        index += 1;
    }
    Ok(())
}

/// The node walk's state: what the file has given so far, and what it refers to.
struct Loader<'a> {
    file: ModelFile<'a>,
    buffers: Vec<Vec<u8>>,
    /// Decoded images by (glTF image index, repeat, sRGB).
    images: HashMap<(usize, bool, bool), Arc<ImageTexture>>,
    materials: Vec<(String, Material)>,
    /// glTF material index -> our material index.
    material_map: HashMap<usize, usize>,
    meshes: Vec<ModelMesh>,
    camera: Option<ModelCamera>,
    /// Orthographic cameras met (named), and perspective ones after the first.
    orthographic: Vec<String>,
    extra_cameras: usize,
    lights: Vec<Light>,
    /// What the file uses that dofray ignores, for the file's one warning.
    ignored: Vec<String>,
    visits: u64,
    /// Every (glTF mesh, world transform bits) built so far: a mesh placed again where it
    /// already is is skipped ([`Loader::node`]).
    placed: HashSet<(usize, [u32; 12])>,
    /// Placements skipped so, for the warning.
    repeats: u64,
}

/// Deepest node nesting followed.
const MAX_DEPTH: usize = 256;

/// Triangles a primitive declares (from its index or position count), without reading data.
fn declared_triangles(prim: &::gltf::Primitive) -> u64 {
    let count = prim
        .indices()
        .or_else(|| prim.get(&::gltf::Semantic::Positions))
        .map_or(0, |a| a.count() as u64);
    match prim.mode() {
        Mode::Triangles => count / 3,
        Mode::TriangleStrip | Mode::TriangleFan => count.saturating_sub(2),
        _ => 0,
    }
}

/// Counts what walking the node trees under `roots` would build, before anything is built:
/// node instances and triangles, each node counted once per path that reaches it (a node used
/// as a child twice is instanced twice). Cycles are an error; the counts saturate, and beyond
/// the limits of `options` the file is refused with them.
fn check_expansion(
    path: &Path,
    document: &::gltf::Document,
    roots: &[::gltf::Node],
    options: &LoadOptions,
) -> Result<(), LoadError> {
    let nodes: Vec<::gltf::Node> = document.nodes().collect();
    let own: Vec<u64> = nodes
        .iter()
        .map(|n| {
            n.mesh().map_or(0, |m| {
                m.primitives()
                    .map(|p| declared_triangles(&p))
                    .fold(0u64, u64::saturating_add)
            })
        })
        .collect();
    // Per node: (instances, triangles) of its subtree, once known. Iterative depth-first
    // search, so a long chain cannot overflow the stack.
    let mut done: Vec<Option<(u64, u64)>> = vec![None; nodes.len()];
    let mut on_stack = vec![false; nodes.len()];
    for start in 0..nodes.len() {
        if done[start].is_some() {
            continue;
        }
        let mut stack: Vec<(usize, Vec<usize>, usize)> = Vec::new();
        let children = |i: usize| nodes[i].children().map(|c| c.index()).collect::<Vec<_>>();
        stack.push((start, children(start), 0));
        on_stack[start] = true;
        while let Some((node, kids, next)) = stack.last_mut() {
            if let Some(&child) = kids.get(*next) {
                *next += 1;
                if on_stack[child] {
                    return Err(gltf_error(
                        path,
                        format!(
                            "node {node} lists node {child} as a child, but node {child} is \
                             node {node} or one of its ancestors: the node graph has a cycle \
                             (expected a tree)"
                        ),
                    ));
                }
                if done[child].is_none() {
                    on_stack[child] = true;
                    let grandchildren = children(child);
                    stack.push((child, grandchildren, 0));
                }
                continue;
            }
            let node = *node;
            let (mut instances, mut triangles) = (1u64, own[node]);
            for &c in kids.iter() {
                let (i, t) = done[c].expect("children finish first");
                instances = instances.saturating_add(i);
                triangles = triangles.saturating_add(t);
            }
            done[node] = Some((instances, triangles));
            on_stack[node] = false;
            stack.pop();
        }
    }
    let (instances, triangles) = roots.iter().fold((0u64, 0u64), |(i, t), r| {
        let (ri, rt) = done[r.index()].unwrap_or((0, 0));
        (i.saturating_add(ri), t.saturating_add(rt))
    });
    check_expansion_limits(path, instances, triangles, options)
}

/// Refuses a node tree that expands to more triangles or node instances than `options` allow
/// (the counts saturate at `u64::MAX`, said as "or more").
fn check_expansion_limits(
    path: &Path,
    instances: u64,
    triangles: u64,
    options: &LoadOptions,
) -> Result<(), LoadError> {
    let count = |n: u64| {
        if n == u64::MAX {
            format!("{n} or more")
        } else {
            n.to_string()
        }
    };
    let limit = |message: String| LoadError::Limit {
        at: Location::file(path),
        message,
    };
    if triangles > options.max_instanced_triangles {
        return Err(limit(format!(
            "the node tree instances {} triangles ({} node instances; a node used as a child \
             several times is counted each time), more than the limit of {} (raise it with \
             --max-instanced-triangles or LoadOptions::max_instanced_triangles)",
            count(triangles),
            count(instances),
            options.max_instanced_triangles
        )));
    }
    if instances > options.max_node_instances {
        return Err(limit(format!(
            "the node tree expands to {} node instances (a node used as a child several times \
             is counted each time), more than the limit of {} (raise \
             LoadOptions::max_node_instances for larger scenes)",
            count(instances),
            options.max_node_instances
        )));
    }
    Ok(())
}

/// Loads a `.gltf` or `.glb` file, applying `transform` on top of its node transforms.
pub fn load(
    path: &Path,
    transform: &Transform,
    textures: &mut TextureCache,
) -> Result<Model, LoadError> {
    let (document, mut loader) = open(ModelFile::new(path, textures))?;
    let roots = roots(&document);
    check_expansion(path, &document, &roots, loader.file.options())?;
    for root in roots {
        let walked = guarded(
            || loader.node(&root, transform, 0),
            || gltf_error(path, "malformed file (reading its data failed)"),
        )?;
        walked?;
    }
    if loader.meshes.is_empty() {
        return Err(gltf_error(path, "no triangle meshes in the scene"));
    }
    Ok(loader.into_model())
}

/// Parses the file and reads its buffers: the document, and a loader ready to walk it.
fn open(file: ModelFile) -> Result<(::gltf::Document, Loader), LoadError> {
    let (document, blob, extensions_used) = parse(&file)?;
    let buffers = read_buffers(&file, &document, blob)?;
    let ignored = ignored_features(&document, &extensions_used);
    let loader = Loader {
        file,
        buffers,
        images: HashMap::new(),
        materials: Vec::new(),
        material_map: HashMap::new(),
        meshes: Vec::new(),
        camera: None,
        orthographic: Vec::new(),
        extra_cameras: 0,
        lights: Vec::new(),
        ignored,
        visits: 0,
        placed: HashSet::new(),
        repeats: 0,
    };
    Ok((document, loader))
}

/// The error of a file the glTF parser refuses.
fn invalid(path: &Path, e: &dyn std::fmt::Display) -> LoadError {
    gltf_error(
        path,
        format!("not a valid glTF 2.0 file (expected .gltf JSON or .glb): {e}"),
    )
}

/// A parsed file: its document, the GLB binary chunk and the extensions it uses.
type Parsed = (::gltf::Document, Option<Vec<u8>>, Vec<String>);

/// Reads and parses the file; its bytes are freed before any buffer is read.
fn parse(file: &ModelFile) -> Result<Parsed, LoadError> {
    let bytes = file.read()?;
    check_glb_length(file.path, &bytes)?;
    guarded(
        || parse_document(file.path, &bytes),
        || gltf_error(file.path, "malformed file (the glTF parser failed on it)"),
    )?
}

/// Parses the JSON (and GLB container) without the parser's validation, checks what that
/// validation would trip over, then validates.
fn parse_document(path: &Path, bytes: &[u8]) -> Result<Parsed, LoadError> {
    let ::gltf::Gltf { document, blob } =
        ::gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| invalid(path, &e))?;
    let mut root = document.into_json();
    if let Some(ext) = root
        .extensions_required
        .iter()
        .find(|e| !SUPPORTED_EXTENSIONS.contains(&e.as_str()))
    {
        return Err(gltf_error(
            path,
            format!(
                "the file requires glTF extension {ext:?} (extensionsRequired), which \
                 dofray does not implement (supported: {})",
                SUPPORTED_EXTENSIONS.join(", ")
            ),
        ));
    }
    // Required extensions are all ours: the parser need not check them against its own.
    root.extensions_required.clear();
    let used = root.extensions_used.clone();
    check_primitive_accessors(path, &root)?;
    let document = ::gltf::Document::from_json(root).map_err(|e| invalid(path, &e))?;
    Ok((document, blob, used))
}

/// gltf's validation indexes accessors by the primitives' POSITION before checking them:
/// an accessor index past the end is refused here first.
fn check_primitive_accessors(path: &Path, root: &::gltf::json::Root) -> Result<(), LoadError> {
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let refs = prim.attributes.values().chain(prim.indices.as_ref());
            if let Some(bad) = refs.map(|i| i.value()).find(|&i| i >= root.accessors.len()) {
                return Err(invalid(
                    path,
                    &format!(
                        "mesh {m} primitive {p} refers to accessor {bad}, but there are {}",
                        root.accessors.len()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The document's buffers: the GLB binary chunk, or files and data URIs, each as long as
/// the document declares.
fn read_buffers(
    file: &ModelFile,
    document: &::gltf::Document,
    mut blob: Option<Vec<u8>>,
) -> Result<Vec<Vec<u8>>, LoadError> {
    let path = file.path;
    let mut buffers = Vec::new();
    for buffer in document.buffers() {
        let data = match buffer.source() {
            ::gltf::buffer::Source::Bin => blob.take().ok_or_else(|| {
                gltf_error(
                    path,
                    format!(
                        "buffer {} refers to a missing GLB binary chunk",
                        buffer.index()
                    ),
                )
            })?,
            ::gltf::buffer::Source::Uri(uri) => read_uri(file, uri, "buffer")?,
        };
        if data.len() < buffer.length() {
            return Err(gltf_error(
                path,
                format!(
                    "buffer {} has {} bytes, expected {} (truncated file?)",
                    buffer.index(),
                    data.len(),
                    buffer.length()
                ),
            ));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

/// The nodes the walk starts from: the default scene's (else the first scene's); with no
/// scene, every node that is nobody's child.
fn roots(document: &::gltf::Document) -> Vec<::gltf::Node<'_>> {
    match document
        .default_scene()
        .or_else(|| document.scenes().next())
    {
        Some(scene) => scene.nodes().collect(),
        None => {
            let mut child = vec![false; document.nodes().len()];
            for n in document.nodes() {
                for c in n.children() {
                    child[c.index()] = true;
                }
            }
            document.nodes().filter(|n| !child[n.index()]).collect()
        }
    }
}

impl Loader<'_> {
    /// The model the walk built, with the file's one warning (the cameras it passed over
    /// join what the document uses and dofray ignores).
    fn into_model(self) -> Model {
        let mut ignored = self.ignored;
        if !self.orthographic.is_empty() {
            ignored.push(format!(
                "orthographic {} {} (dofray renders perspective views only)",
                plural(self.orthographic.len(), "camera", "cameras"),
                self.orthographic.join(", ")
            ));
        }
        if self.extra_cameras > 0 {
            ignored.push(format!(
                "{} after the first perspective one",
                plural(self.extra_cameras, "camera", "cameras")
            ));
        }
        let orthographic_camera = match self.camera {
            None => self.orthographic.first().cloned(),
            Some(_) => None,
        };
        let mut warnings: Vec<String> = warning(self.file.path, &ignored).into_iter().collect();
        if self.repeats > 0 {
            warnings.push(format!(
                "{}: skipped {} of a mesh where the same mesh already is (the same \
                 world transform): coincident copies add nothing to the image",
                shown(self.file.path),
                plural(self.repeats as usize, "placement", "placements"),
            ));
        }
        Model {
            meshes: self.meshes,
            materials: self.materials,
            camera: self.camera,
            orthographic_camera,
            lights: self.lights,
            warnings,
        }
    }
}

/// `1 camera`, `2 cameras`.
fn plural(n: usize, one: &str, many: &str) -> String {
    if n == 1 {
        format!("1 {one}")
    } else {
        format!("{n} {many}")
    }
}

/// A named glTF object for messages: `light 1 "Spot"`.
/// Reads the `dofray_*` depth-of-field properties of one `extras` value (JSON text) into
/// `dof`; other properties, and extras that are not an object, are left alone. `Err` names the
/// property and what it must be.
fn camera_dof(json: &str, dof: &mut CameraDof) -> Result<(), (&'static str, String)> {
    let Ok(serde_json::Value::Object(map)) = serde_json::from_str::<serde_json::Value>(json) else {
        return Ok(());
    };
    let number = |key: &'static str, positive: bool| -> Result<Option<f32>, _> {
        let Some(v) = map.get(key) else {
            return Ok(None);
        };
        let x = v.as_f64().map(|x| x as f32);
        match x {
            Some(x) if x.is_finite() && (!positive || x > 0.0) => Ok(Some(x)),
            _ => Err((
                key,
                format!(
                    "expected a finite number{}, got {v}",
                    if positive { " > 0" } else { "" }
                ),
            )),
        }
    };
    let set = |slot: &mut Option<f32>, v: Option<f32>| {
        if v.is_some() {
            *slot = v;
        }
    };
    set(&mut dof.f_number, number("dofray_f_number", true)?);
    set(
        &mut dof.focus_distance,
        number("dofray_focus_distance", true)?,
    );
    set(
        &mut dof.focal_length_mm,
        number("dofray_focal_length_mm", true)?,
    );
    set(
        &mut dof.sensor_width_mm,
        number("dofray_sensor_width_mm", true)?,
    );
    set(
        &mut dof.blade_rotation_deg,
        number("dofray_blade_rotation", false)?,
    );
    set(&mut dof.anamorphic, number("dofray_anamorphic", true)?);
    if let Some(v) = map.get("dofray_blades") {
        match v.as_u64() {
            Some(b) if b == 0 || (3..=1024).contains(&b) => dof.blades = Some(b as u32),
            _ => {
                return Err((
                    "dofray_blades",
                    format!(
                        "expected 0 (round) or a whole number of blades from 3 to 1024, got {v}"
                    ),
                ));
            }
        }
    }
    Ok(())
}

fn named(kind: &str, index: usize, name: Option<&str>) -> String {
    match name {
        Some(n) => format!("{kind} {index} {n:?}"),
        None => format!("{kind} {index}"),
    }
}

/// The one warning line of a file: what it uses that dofray ignores (`None` if nothing).
fn warning(path: &Path, ignored: &[String]) -> Option<String> {
    const SHOWN: usize = 12;
    if ignored.is_empty() {
        return None;
    }
    let mut list = ignored[..ignored.len().min(SHOWN)].join("; ");
    if ignored.len() > SHOWN {
        list.push_str(&format!("; and {} more", ignored.len() - SHOWN));
    }
    Some(format!(
        "{}: ignored what dofray does not support: {list}",
        shown(path)
    ))
}

/// What the document uses that the loader does not honour, found before the node walk (the
/// walk adds cameras and light ranges).
fn ignored_features(document: &::gltf::Document, extensions_used: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    let unsupported: Vec<&str> = extensions_used
        .iter()
        .map(String::as_str)
        .filter(|e| !SUPPORTED_EXTENSIONS.contains(e))
        .collect();
    if !unsupported.is_empty() {
        out.push(format!("extensions {}", unsupported.join(", ")));
    }
    let scenes = document.scenes().len();
    if scenes > 1 {
        out.push(format!(
            "{} other than the one rendered",
            plural(scenes - 1, "scene", "scenes")
        ));
    }
    let animations = document.animations().len();
    if animations > 0 {
        out.push(plural(animations, "animation", "animations"));
    }
    let skins = document.skins().len();
    if skins > 0 {
        out.push(format!(
            "{} (meshes are drawn unskinned)",
            plural(skins, "skin", "skins")
        ));
    }
    ignored_in_meshes(document, &mut out);
    ignored_in_materials(document, &mut out);
    out
}

/// What the meshes' primitives carry that is not drawn: morph targets, points and lines,
/// vertex colours, texture coordinate sets other than the one loaded.
fn ignored_in_meshes(document: &::gltf::Document, out: &mut Vec<String>) {
    let (mut morphs, mut lines, mut colours, mut uv_sets) = (Vec::new(), Vec::new(), false, false);
    for mesh in document.meshes() {
        for prim in mesh.primitives() {
            if prim.morph_targets().next().is_some() && !morphs.contains(&mesh.index()) {
                morphs.push(mesh.index());
            }
            if !matches!(
                prim.mode(),
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) && !lines.contains(&mesh.index())
            {
                lines.push(mesh.index());
            }
            for (semantic, _) in prim.attributes() {
                match semantic {
                    ::gltf::Semantic::Colors(_) => colours = true,
                    ::gltf::Semantic::TexCoords(n) if n != uv_set(&prim.material()) => {
                        uv_sets = true
                    }
                    _ => {}
                }
            }
        }
    }
    let list = |v: &[usize]| {
        v.iter()
            .map(usize::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    };
    if !morphs.is_empty() {
        out.push(format!("morph targets (meshes {})", list(&morphs)));
    }
    if !lines.is_empty() {
        out.push(format!(
            "point and line primitives (meshes {})",
            list(&lines)
        ));
    }
    if colours {
        out.push("vertex colours (COLOR_n)".into());
    }
    if uv_sets {
        out.push("texture coordinate sets other than the one each primitive is loaded with".into());
    }
}

/// What the materials ask of textures that is not honoured: occlusion textures, and sampler
/// settings (only wrapS is honoured, for both directions, MIRRORED_REPEAT as REPEAT; lookups
/// are always bilinear).
fn ignored_in_materials(document: &::gltf::Document, out: &mut Vec<String>) {
    use ::gltf::texture::MagFilter;
    let mut samplers = Vec::new();
    for material in document.materials() {
        let pbr = material.pbr_metallic_roughness();
        let textures = [
            pbr.base_color_texture().map(|t| t.texture()),
            material.emissive_texture().map(|t| t.texture()),
            pbr.metallic_roughness_texture().map(|t| t.texture()),
            material.normal_texture().map(|t| t.texture()),
        ];
        for texture in textures.into_iter().flatten() {
            let sampler = texture.sampler();
            let odd = sampler.wrap_s() != sampler.wrap_t()
                || sampler.wrap_s() == WrappingMode::MirroredRepeat
                || sampler.mag_filter() == Some(MagFilter::Nearest);
            let key = sampler
                .index()
                .map_or_else(|| "default".to_string(), |i| i.to_string());
            if odd && !samplers.contains(&key) {
                samplers.push(key);
            }
        }
        if material.occlusion_texture().is_some() {
            push_once(out, "occlusion textures");
        }
    }
    if !samplers.is_empty() {
        out.push(format!(
            "sampler settings (samplers {}: wrapT, MIRRORED_REPEAT and NEAREST filtering; \
             dofray wraps both directions by wrapS and filters bilinearly)",
            samplers.join(", ")
        ));
    }
}

fn push_once(out: &mut Vec<String>, item: &str) {
    if !out.iter().any(|o| o == item) {
        out.push(item.to_string());
    }
}

impl Loader<'_> {
    /// Walks `node` and its subtree under the transform `parent`, `depth` levels down.
    fn node(
        &mut self,
        node: &::gltf::Node,
        parent: &Transform,
        depth: usize,
    ) -> Result<(), LoadError> {
        self.visits += 1;
        if depth > MAX_DEPTH || self.visits > self.file.options().max_node_instances {
            return Err(gltf_error(
                self.file.path,
                format!(
                    "node {}: the node tree is nested more than {MAX_DEPTH} levels deep",
                    node.index()
                ),
            ));
        }
        let local = Mat4::from_cols_array_2d(&node.transform().matrix());
        let local = Affine3A::from_mat4(local);
        let world = Transform::new(local)
            .and_then(|l| parent.after(&l))
            .ok_or_else(|| {
                gltf_error(
                    self.file.path,
                    format!("node {}: singular or non-finite transform", node.index()),
                )
            })?;
        if let Some(camera) = node.camera() {
            self.camera(node, &camera, &world)?;
        }
        if let Some(light) = node.light() {
            self.light(node, &light, &world)?;
        }
        if let Some(m) = node.mesh() {
            // The same mesh placed again by the same world transform (bit for bit) adds only
            // coincident triangles: nothing to the image, but a BVH cannot separate them, so
            // every ray there would test every copy (a node tree that instances one triangle
            // half a million times in one place took minutes a frame). Repeats are skipped,
            // as the OBJ loader drops repeated triangles.
            let key = world.affine.to_cols_array().map(f32::to_bits);
            if self.placed.insert((m.index(), key)) {
                for prim in m.primitives() {
                    self.primitive(&m, &prim, &world)?;
                }
            } else {
                self.repeats += 1;
            }
        }
        for child in node.children() {
            self.node(&child, &world, depth + 1)?;
        }
        Ok(())
    }

    /// A camera at `node` (world transform `world`): the first usable perspective one is the
    /// model's; the others are counted, and orthographic ones named, for the warning.
    fn camera(
        &mut self,
        node: &::gltf::Node,
        camera: &::gltf::Camera,
        world: &Transform,
    ) -> Result<(), LoadError> {
        match camera.projection() {
            ::gltf::camera::Projection::Perspective(_) if self.camera.is_some() => {
                self.extra_cameras += 1;
            }
            ::gltf::camera::Projection::Perspective(p) => {
                let eye = world.affine.transform_point3(Vec3::ZERO);
                let forward = world
                    .affine
                    .transform_vector3(Vec3::NEG_Z)
                    .normalize_or_zero();
                let up = world.affine.transform_vector3(Vec3::Y).normalize_or_zero();
                let vfov_deg = p.yfov().to_degrees();
                if eye.is_finite() && forward != Vec3::ZERO && check_vfov(vfov_deg).is_ok() {
                    // The camera data's properties, then its node's (the object's) over them.
                    let mut dof = CameraDof::default();
                    let sources = [
                        (
                            camera.extras(),
                            format!("cameras[{}].extras", camera.index()),
                        ),
                        (node.extras(), format!("nodes[{}].extras", node.index())),
                    ];
                    for (extras, key) in sources {
                        if let Some(raw) = extras {
                            camera_dof(raw.get(), &mut dof).map_err(|(k, message)| {
                                LoadError::Gltf {
                                    at: Location::file(self.file.path)
                                        .with_key(format!("{key}.{k}")),
                                    message,
                                }
                            })?;
                        }
                    }
                    self.camera = Some(ModelCamera {
                        eye,
                        forward,
                        up,
                        vfov_deg,
                        aspect: p.aspect_ratio(),
                        dof,
                    });
                } else {
                    self.extra_cameras += 1;
                }
            }
            ::gltf::camera::Projection::Orthographic(_) => {
                let name = named("camera", camera.index(), camera.name());
                self.orthographic
                    .push(format!("{name} (node {})", node.index()));
            }
        }
        Ok(())
    }

    /// A KHR_lights_punctual light at `node` (world transform `world`): glTF lights shine
    /// down the node's local -Z; candela (point, spot) and lux (directional) become W/sr and
    /// W/m^2 by dividing by [`LUMENS_PER_WATT`], times the light's colour.
    fn light(
        &mut self,
        node: &::gltf::Node,
        light: &::gltf::khr_lights_punctual::Light,
        world: &Transform,
    ) -> Result<(), LoadError> {
        use ::gltf::khr_lights_punctual::Kind;
        let name = named("light", light.index(), light.name());
        let fail = |message: String| LoadError::Gltf {
            at: Location::file(self.file.path).with_key(format!(
                "extensions.KHR_lights_punctual.lights[{}]",
                light.index()
            )),
            message: format!("{name}: {message}"),
        };
        let power = light_power(light).map_err(fail)?;
        if let Some(range) = light.range() {
            self.ignored.push(format!(
                "{name} range {} (dofray lights reach every distance, falling off as 1/d^2)",
                short_number(range)
            ));
        }
        let position = world.affine.transform_point3(Vec3::ZERO);
        let direction = world
            .affine
            .transform_vector3(Vec3::NEG_Z)
            .normalize_or_zero();
        if !(position.is_finite() && direction.is_finite() && direction != Vec3::ZERO) {
            return Err(fail(format!(
                "node {}'s transform gives no finite position and direction",
                node.index()
            )));
        }
        self.lights.push(match light.kind() {
            Kind::Point => Light::Point {
                position,
                intensity: power,
            },
            Kind::Directional => Light::Directional {
                direction,
                irradiance: power,
                angle: 0.0,
            },
            Kind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => {
                let right = std::f32::consts::FRAC_PI_2;
                // The extension asks for inner < outer; Blender writes inner = outer for a
                // spot without blend, a hard edge, which is accepted.
                if !((0.0..=right).contains(&outer_cone_angle)
                    && (0.0..=outer_cone_angle).contains(&inner_cone_angle))
                {
                    return Err(fail(format!(
                        "spot cone angles innerConeAngle {} and outerConeAngle {} must satisfy \
                         0 <= inner <= outer <= pi/2 (radians)",
                        short_number(inner_cone_angle),
                        short_number(outer_cone_angle)
                    )));
                }
                Light::Spot {
                    position,
                    direction,
                    intensity: power,
                    inner_angle: inner_cone_angle,
                    outer_angle: outer_cone_angle,
                    radius: 0.0,
                }
            }
        });
        Ok(())
    }

    /// One triangle primitive as a mesh in world space (points and lines have no surface and
    /// are skipped; so is a primitive without triangles).
    fn primitive(
        &mut self,
        m: &::gltf::Mesh,
        prim: &::gltf::Primitive,
        world: &Transform,
    ) -> Result<(), LoadError> {
        let mode = prim.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            return Ok(());
        }
        let what = format!("mesh {} primitive {}", m.index(), prim.index());
        let attributes = self.check_attributes(prim, &what)?;
        let mut buffers = self.read_vertices(prim, &attributes, world)?;
        buffers.triangles = self.read_triangles(prim, mode, buffers.positions.len())?;
        keep_winding(&mut buffers.triangles, world);
        if buffers.triangles.is_empty() || buffers.positions.is_empty() {
            return Ok(());
        }
        let material = prim.material();
        let material = match material.index() {
            Some(i) => Some(self.material(&material, i)?),
            None => None,
        };
        // Normal-mapped materials need tangents, which need texture coordinates.
        let normal_mapped = material.is_some_and(|i| self.materials[i].1.maps.normal.is_some());
        let b = &buffers;
        let tangents = match &b.uvs {
            Some(uv) if normal_mapped => {
                let given = self.read_tangents(prim, world, b.positions.len())?;
                match given {
                    Some(t) => Some(t),
                    None => Some(
                        compute_tangents(&b.positions, &b.triangles, b.normals.as_deref(), uv)
                            .map_err(|e| super::mesh_input::memory_error(self.file.path, e))?,
                    ),
                }
            }
            _ => None,
        };
        buffers.tangents = tangents;
        let mesh = self.file.mesh(&what, buffers)?;
        self.meshes.push(ModelMesh { mesh, material });
        Ok(())
    }

    /// Checks that reading `accessor` cannot go out of its buffer or hit a type the reader
    /// does not expect ([`check_accessor`]).
    fn check(
        &self,
        accessor: &::gltf::Accessor,
        what: &str,
        dims: Dimensions,
        types: &[DataType],
    ) -> Result<(), LoadError> {
        check_accessor(self.file.path, &self.buffers, accessor, what, dims, types)
    }

    /// Checks the accessors a primitive is read from, before any is read.
    fn check_attributes(
        &self,
        prim: &::gltf::Primitive,
        what: &str,
    ) -> Result<Attributes, LoadError> {
        let positions = prim
            .get(&::gltf::Semantic::Positions)
            .ok_or_else(|| gltf_error(self.file.path, format!("{what}: no POSITION attribute")))?;
        self.check(&positions, "POSITION", Dimensions::Vec3, &[DataType::F32])?;
        let normals = prim.get(&::gltf::Semantic::Normals);
        if let Some(n) = &normals {
            self.check(n, "NORMAL", Dimensions::Vec3, &[DataType::F32])?;
        }
        if let Some(i) = prim.indices() {
            let types = [DataType::U8, DataType::U16, DataType::U32];
            self.check(&i, "indices", Dimensions::Scalar, &types)?;
        }
        let uv_set = uv_set(&prim.material());
        let uvs = prim.get(&::gltf::Semantic::TexCoords(uv_set));
        if let Some(t) = &uvs {
            let types = [DataType::F32, DataType::U8, DataType::U16];
            self.check(t, "TEXCOORD", Dimensions::Vec2, &types)?;
        }
        Ok(Attributes {
            count: positions.count(),
            normals: normals.is_some(),
            uv_set: uvs.map(|_| uv_set),
        })
    }

    /// Positions, normals and texture coordinates in world space (no triangles yet); normals
    /// and texture coordinates only when there is one for every position. Buffers sized by
    /// the accessors are allocated fallibly (a resource-limit error naming the file).
    fn read_vertices(
        &self,
        prim: &::gltf::Primitive,
        attributes: &Attributes,
        world: &Transform,
    ) -> Result<MeshBuffers, LoadError> {
        let path = self.file.path;
        let count = attributes.count;
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(Vec::as_slice));
        let mut p = buffer(path, count + 1, "a mesh's positions")?;
        if let Some(it) = reader.read_positions() {
            p.extend(it.map(|v| world.point(v)));
        }
        let mut n = None;
        if let Some(it) = attributes.normals.then(|| reader.read_normals()).flatten() {
            let mut normals = buffer(path, count, "a mesh's normals")?;
            normals.extend(it.map(|v| world.normal(v)));
            n = (normals.len() == p.len()).then_some(normals);
        }
        let mut uv = None;
        if let Some(it) = attributes
            .uv_set
            .and_then(|set| reader.read_tex_coords(set))
        {
            let mut uvs = buffer(path, count, "a mesh's texture coordinates")?;
            // glTF's v runs down the image; ours runs up.
            uvs.extend(it.into_f32().map(|[u, v]| [u, 1.0 - v]));
            uv = (uvs.len() == p.len()).then_some(uvs);
        }
        Ok(MeshBuffers {
            positions: p,
            triangles: Vec::new(),
            normals: n,
            uvs: uv,
            tangents: None,
        })
    }

    /// The primitive's triangles, from its indices or else its vertex order; strips and fans
    /// unrolled (every other strip triangle flipped to keep the winding). Allocated fallibly.
    fn read_triangles(
        &self,
        prim: &::gltf::Primitive,
        mode: Mode,
        vertices: usize,
    ) -> Result<Vec<[u32; 3]>, LoadError> {
        let path = self.file.path;
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(Vec::as_slice));
        let indices = prim
            .indices()
            .and_then(|_| reader.read_indices())
            .map(|r| r.into_u32());
        if mode == Mode::Triangles {
            // Straight into triangles (one spare slot for TriangleMesh's padding).
            let count = prim.indices().map_or(vertices, |a| a.count()) / 3;
            let mut t = buffer(path, count + 1, "a mesh's triangles")?;
            match indices {
                Some(mut it) => {
                    while let (Some(a), Some(b), Some(c)) = (it.next(), it.next(), it.next()) {
                        t.push([a, b, c]);
                    }
                }
                None => t.extend((0..count as u32).map(|i| [3 * i, 3 * i + 1, 3 * i + 2])),
            }
            return Ok(t);
        }
        let count = prim.indices().map_or(vertices, |a| a.count());
        let mut idx = buffer(path, count, "a mesh's indices")?;
        match indices {
            Some(it) => idx.extend(it),
            None => idx.extend(0..vertices as u32),
        }
        let mut t = buffer(path, idx.len().saturating_sub(2) + 1, "a mesh's triangles")?;
        if mode == Mode::TriangleStrip {
            t.extend(idx.windows(3).enumerate().map(|(i, w)| {
                if i % 2 == 0 {
                    [w[0], w[1], w[2]]
                } else {
                    [w[1], w[0], w[2]]
                }
            }));
        } else {
            t.extend((2..idx.len()).map(|i| [idx[0], idx[i - 1], idx[i]]));
        }
        Ok(t)
    }

    /// The primitive's TANGENT attribute in world space, when it has one for every vertex: w
    /// is the bitangent sign, flipped with the winding by a mirroring transform.
    fn read_tangents(
        &self,
        prim: &::gltf::Primitive,
        world: &Transform,
        vertices: usize,
    ) -> Result<Option<Vec<[f32; 4]>>, LoadError> {
        let Some(t) = prim.get(&::gltf::Semantic::Tangents) else {
            return Ok(None);
        };
        self.check(&t, "TANGENT", Dimensions::Vec4, &[DataType::F32])?;
        let flip = if world.mirrors { -1.0 } else { 1.0 };
        Ok(prim
            .reader(|b| self.buffers.get(b.index()).map(Vec::as_slice))
            .read_tangents()
            .map(|it| {
                it.map(|[x, y, z, w]| {
                    let v = world.affine.transform_vector3(Vec3::new(x, y, z));
                    [v.x, v.y, v.z, w * flip]
                })
                .collect::<Vec<_>>()
            })
            .filter(|t| t.len() == vertices))
    }

    /// Our index of glTF material `index`, converted on first use.
    fn material(&mut self, m: &::gltf::Material, index: usize) -> Result<usize, LoadError> {
        if let Some(&i) = self.material_map.get(&index) {
            return Ok(i);
        }
        let at = Location::file(self.file.path).with_key(format!("materials[{index}]"));
        let pbr = m.pbr_metallic_roughness();
        let [r, g, b, a] = pbr.base_color_factor();
        let base = Vec3::new(r, g, b);
        let base = if base.is_finite() {
            base.max(Vec3::ZERO)
        } else {
            Vec3::ONE
        };
        let uv = uv_set(m);
        let base_image = match pbr.base_color_texture() {
            Some(info) => Some(self.texture_image(&info.texture(), true)?),
            None => None,
        };
        let metallic = unit_factor(pbr.metallic_factor(), 0.0);
        let roughness = unit_factor(pbr.roughness_factor(), 1.0);
        // KHR_materials_transmission (its texture is not read: the factor applies everywhere),
        // KHR_materials_ior, and KHR_materials_volume's presence (a solid, not a thin wall).
        let transmission = m
            .transmission()
            .map_or(0.0, |t| unit_factor(t.transmission_factor(), 0.0));
        let ior = m
            .ior()
            .filter(|i| i.is_finite() && (1.0..=10.0).contains(i))
            .unwrap_or(1.5);
        // Thin-walled only when KHR_materials_volume says so (thickness 0). glTF reads a
        // transmissive material without the extension as thin-walled, but Blender's exporter
        // writes its glass that way and Cycles renders it as a refracting solid: dofray
        // follows the renderer the file came from.
        let thin = m.volume().is_some_and(|v| v.thickness_factor() <= 0.0);
        // A metallic-roughness texture on the mesh's texture coordinates makes metalness and
        // roughness vary per hit; one on another set is ignored (the factors apply).
        let metal_rough = match pbr.metallic_roughness_texture() {
            Some(info) if info.tex_coord() == uv => {
                Some(self.texture_image(&info.texture(), false)?)
            }
            _ => None,
        };
        let maps = MaterialMaps {
            alpha: alpha(m, &at, a, &base_image)?,
            metal_rough,
            normal: self.normal_map(m, &at, uv)?,
        };
        let name = m
            .name()
            .map_or_else(|| format!("material {index}"), str::to_string);
        let (emission, emission_texture) = self.emission(m, &at, uv)?;
        self.materials.push((
            name,
            Material {
                base_color: textured(&base_image, base),
                metallic,
                roughness,
                transmission,
                ior,
                thin,
                emission,
                emission_texture,
                one_sided: false,
                maps,
                light: None,
            },
        ));
        let i = self.materials.len() - 1;
        self.material_map.insert(index, i);
        Ok(i)
    }

    /// The material's normal map: tangent space, on the mesh's texture coordinates `uv` (one
    /// on another set is ignored).
    fn normal_map(
        &mut self,
        m: &::gltf::Material,
        at: &Location,
        uv: u32,
    ) -> Result<Option<NormalMap>, LoadError> {
        let Some(info) = m.normal_texture().filter(|info| info.tex_coord() == uv) else {
            return Ok(None);
        };
        let scale = info.scale();
        if !(scale.is_finite() && scale.abs() <= MAX_MATERIAL_VALUE) {
            return Err(LoadError::Gltf {
                at: at.clone(),
                message: format!(
                    "normalTexture scale {} is out of range (expected a finite number of \
                     magnitude at most 1e6)",
                    short_number(scale)
                ),
            });
        }
        Ok(Some(NormalMap {
            image: self.texture_image(&info.texture(), false)?,
            scale,
        }))
    }

    /// The material's emission: emissiveFactor times KHR_materials_emissive_strength, with
    /// emissiveTexture when it uses the mesh's texture coordinates `uv` (and there is any).
    fn emission(
        &mut self,
        m: &::gltf::Material,
        at: &Location,
        uv: u32,
    ) -> Result<(Vec3, Option<Arc<ImageTexture>>), LoadError> {
        let strength = m.emissive_strength().unwrap_or(1.0);
        let emission = Vec3::from(m.emissive_factor()) * strength;
        if !(emission.is_finite() && emission.max_element() <= MAX_MATERIAL_VALUE) {
            return Err(LoadError::Gltf {
                at: at.clone(),
                message: format!(
                    "emission {} (emissiveFactor times emissiveStrength {}) is out of range: \
                     each component must be finite and at most 1e6",
                    short_vec(emission),
                    short_number(strength)
                ),
            });
        }
        let emission = emission.max(Vec3::ZERO);
        let texture = match m.emissive_texture() {
            Some(info) if emission != Vec3::ZERO && info.tex_coord() == uv => {
                Some(self.texture_image(&info.texture(), true)?)
            }
            _ => None,
        };
        Ok((emission, texture))
    }
    /// The image of a texture, with its sampler's wrap mode (wrapS clamp-to-edge gives clamp,
    /// else repeat).
    fn texture_image(
        &mut self,
        texture: &::gltf::Texture,
        srgb: bool,
    ) -> Result<Arc<ImageTexture>, LoadError> {
        let wrap = match texture.sampler().wrap_s() {
            WrappingMode::ClampToEdge => Wrap::Clamp,
            _ => Wrap::Repeat,
        };
        self.image(&texture.source(), wrap, srgb)
    }

    /// A glTF image decoded once per (image, wrap, sRGB): from a buffer view, a data URI, or
    /// a file shared through the texture cache.
    fn image(
        &mut self,
        image: &::gltf::Image,
        wrap: Wrap,
        srgb: bool,
    ) -> Result<Arc<ImageTexture>, LoadError> {
        let key = (image.index(), wrap == Wrap::Repeat, srgb);
        if let Some(t) = self.images.get(&key) {
            return Ok(t.clone());
        }
        let what = format!("image {}", image.index());
        let path = self.file.path;
        let texture = match image.source() {
            ::gltf::image::Source::View { view, .. } => {
                let bytes = self
                    .buffers
                    .get(view.buffer().index())
                    .and_then(|b| b.get(view.offset()..view.offset().checked_add(view.length())?))
                    .ok_or_else(|| gltf_error(path, format!("{what}: buffer view out of range")))?;
                self.decode(bytes, srgb, wrap, &what)?
            }
            ::gltf::image::Source::Uri { uri, .. }
                if !uri.starts_with("data:") && !uri.contains(':') =>
            {
                let name = uri_file_name(path, uri, &what)?;
                let (dir, at) = (Path::new(""), Location::file(path));
                self.file.texture((dir, &name), srgb, wrap, at)?
            }
            ::gltf::image::Source::Uri { uri, .. } => {
                let bytes = read_uri(&self.file, uri, "image")?;
                self.decode(&bytes, srgb, wrap, &what)?
            }
        };
        self.images.insert(key, texture.clone());
        Ok(texture)
    }

    /// Decodes an image held in the file (a buffer view or a data URI).
    fn decode(
        &self,
        bytes: &[u8],
        srgb: bool,
        wrap: Wrap,
        what: &str,
    ) -> Result<Arc<ImageTexture>, LoadError> {
        let t = decode(bytes, srgb, wrap, self.file.options().max_texture_bytes)
            .map_err(|m| gltf_error(self.file.path, format!("{what}: {m}")))?;
        Ok(Arc::new(t))
    }
}

/// A light's colour times its intensity in dofray's radiometric units (W/sr for point and
/// spot lights, W/m^2 for directional ones), or why the file's values are refused.
fn light_power(light: &::gltf::khr_lights_punctual::Light) -> Result<Vec3, String> {
    let color = Vec3::from(light.color());
    if !(color.is_finite() && color.min_element() >= 0.0) {
        return Err(format!(
            "color {} must be finite and >= 0",
            short_vec(color)
        ));
    }
    let intensity = light.intensity();
    if !(intensity.is_finite() && intensity >= 0.0) {
        return Err(format!(
            "intensity {} must be finite and >= 0",
            short_number(intensity)
        ));
    }
    let power = color * (intensity / LUMENS_PER_WATT);
    if power.max_element() > MAX_LIGHT_VALUE {
        return Err(format!(
            "intensity {} times color is {} W/sr or W/m^2 after dividing by {LUMENS_PER_WATT} \
             lm/W, more than the limit of 1e12",
            short_number(intensity),
            short_vec(power)
        ));
    }
    Ok(power)
}

/// What a triangle primitive's vertices are read from, once its accessors are checked.
struct Attributes {
    /// Vertices (POSITION elements).
    count: usize,
    /// It has normals.
    normals: bool,
    /// The texture coordinate set it is loaded with, when it has that set.
    uv_set: Option<u32>,
}

/// A factor that must lie in [0, 1]: clamped, or `default` when it is not a number.
fn unit_factor(v: f32, default: f32) -> f32 {
    if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        default
    }
}

/// `image` tinted by `tint`, or the plain colour when there is no image.
fn textured(image: &Option<Arc<ImageTexture>>, tint: Vec3) -> Texture {
    match image {
        Some(image) => Texture::Image {
            image: image.clone(),
            tint,
        },
        None => Texture::Constant(tint),
    }
}

/// The material's alpha: baseColorFactor's alpha `a` times the base-colour texture's alpha
/// channel, for MASK (holes below alphaCutoff, default 0.5) and BLEND (stochastic
/// transparency). A material whose alpha cannot fall below what it needs stays opaque (no
/// filter).
fn alpha(
    m: &::gltf::Material,
    at: &Location,
    a: f32,
    base_image: &Option<Arc<ImageTexture>>,
) -> Result<Option<Alpha>, LoadError> {
    let factor = unit_factor(a, 1.0);
    let mode = match m.alpha_mode() {
        ::gltf::material::AlphaMode::Opaque => None,
        ::gltf::material::AlphaMode::Mask => {
            let cutoff = m.alpha_cutoff().unwrap_or(0.5);
            if !(cutoff.is_finite() && cutoff >= 0.0) {
                return Err(LoadError::Gltf {
                    at: at.clone(),
                    message: format!(
                        "alphaCutoff {} is out of range (expected a number >= 0)",
                        short_number(cutoff)
                    ),
                });
            }
            Some(AlphaMode::Mask { cutoff })
        }
        ::gltf::material::AlphaMode::Blend => Some(AlphaMode::Blend),
    };
    Ok(mode.and_then(|mode| Alpha::new(factor, base_image.clone(), mode)))
}

/// Per-vertex tangents from positions and texture coordinates (v up, as loaded): each
/// triangle's dP/du and dP/dv, weighted by its area in UV space, summed at its corners, then
/// made orthogonal to the vertex normal (else the summed face normals); w is the sign that
/// makes `cross(normal, tangent) * w` follow dP/dv. Vertices without a usable UV gradient get
/// any tangent orthogonal to their normal. Not MikkTSpace: seams are not split or welded.
fn compute_tangents(
    p: &[[f32; 3]],
    tris: &[[u32; 3]],
    normals: Option<&[[f32; 3]]>,
    uv: &[[f32; 2]],
) -> Result<Vec<[f32; 4]>, crate::limits::MemoryError> {
    use crate::limits::{try_collect, try_vec};
    let mut t = try_vec(p.len(), Vec3::ZERO, "tangent sums")?;
    let mut b = try_vec(p.len(), Vec3::ZERO, "bitangent sums")?;
    let mut face = try_vec(p.len(), Vec3::ZERO, "face normal sums")?;
    for tri in tris {
        let [i0, i1, i2] = tri.map(|i| i as usize);
        let (Some(&p0), Some(&p1), Some(&p2)) = (p.get(i0), p.get(i1), p.get(i2)) else {
            continue;
        };
        let (p0, p1, p2) = (Vec3::from(p0), Vec3::from(p1), Vec3::from(p2));
        let (w0, w1, w2) = (uv[i0], uv[i1], uv[i2]);
        let (e1, e2) = (p1 - p0, p2 - p0);
        let (du1, dv1) = (w1[0] - w0[0], w1[1] - w0[1]);
        let (du2, dv2) = (w2[0] - w0[0], w2[1] - w0[1]);
        let det = du1 * dv2 - du2 * dv1;
        let n = e1.cross(e2);
        for i in [i0, i1, i2] {
            face[i] += n;
        }
        if det == 0.0 || !det.is_finite() {
            continue;
        }
        // Area-weighted: dividing by |det| only for the sign keeps big triangles heavier.
        let sign = det.signum();
        let tangent = (e1 * dv2 - e2 * dv1) * sign;
        let bitangent = (e2 * du1 - e1 * du2) * sign;
        if !(tangent.is_finite() && bitangent.is_finite()) {
            continue;
        }
        for i in [i0, i1, i2] {
            t[i] += tangent;
            b[i] += bitangent;
        }
    }
    let tangents = (0..p.len()).map(|i| {
        let n = normals
            .and_then(|n| n.get(i))
            .map_or(face[i], |&n| Vec3::from(n))
            .normalize_or_zero();
        let mut tangent = (t[i] - n * n.dot(t[i])).normalize_or_zero();
        if tangent == Vec3::ZERO {
            tangent = if n == Vec3::ZERO {
                Vec3::X
            } else {
                n.any_orthonormal_vector()
            };
        }
        let w = if n.cross(tangent).dot(b[i]) < 0.0 {
            -1.0
        } else {
            1.0
        };
        let tangent = if tangent.is_finite() {
            tangent
        } else {
            Vec3::X
        };
        [tangent.x, tangent.y, tangent.z, w]
    });
    try_collect(tangents, "the tangents")
}

/// The texture coordinate set a primitive is loaded with: the base-colour texture's, else the
/// emissive texture's, else 0.
fn uv_set(material: &::gltf::Material) -> u32 {
    match (
        material.pbr_metallic_roughness().base_color_texture(),
        material.emissive_texture(),
    ) {
        (Some(t), _) | (None, Some(t)) => t.tex_coord(),
        (None, None) => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trips() {
        assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVsbG8").unwrap(), b"hello");
        assert_eq!(base64_decode("").unwrap(), b"");
        assert!(base64_decode("a*b").is_none());
        assert!(base64_decode("aG=Vs").is_none());
    }

    #[test]
    fn percent_escapes_decode() {
        assert_eq!(percent_decode("a%20b.bin"), b"a b.bin");
        assert_eq!(percent_decode("100%"), b"100%");
        assert_eq!(percent_decode("%zz"), b"%zz");
    }
}
