//! Foxglove's well-known message schemas in their JSON encoding (schema
//! encoding `jsonschema`, message encoding `json`), as far as `play` uses them:
//! `foxglove.FrameTransforms` and `foxglove.SceneUpdate` (with every field of
//! Foxglove's documentation, so that the schema text describes the real
//! message), plus the JSON Schema of our plain plot messages.
//!
//! Foxglove recognizes a schema by its name; the JSON Schema text is written
//! here from the field tables of Foxglove's schema reference. Timestamps are
//! `{sec, nsec}` objects, quaternions `{x, y, z, w}` (MuJoCo's are `w, x, y, z`).
use serde::Serialize;
use serde_json::{json, Value};

/// Schema name of a set of transforms.
pub const FRAME_TRANSFORMS: &str = "foxglove.FrameTransforms";
/// Schema name of a 3D scene update.
pub const SCENE_UPDATE: &str = "foxglove.SceneUpdate";

/// A time or a duration: whole seconds and nanoseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Time {
    pub sec: u32,
    pub nsec: u32,
}

impl Time {
    /// From nanoseconds (as MCAP's `log_time`).
    pub fn from_nanos(ns: u64) -> Time {
        Time {
            sec: (ns / 1_000_000_000) as u32,
            nsec: (ns % 1_000_000_000) as u32,
        }
    }
    /// Zero (as a lifetime: the entity stays until replaced).
    pub const ZERO: Time = Time { sec: 0, nsec: 0 };
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl Vector3 {
    pub fn new([x, y, z]: [f64; 3]) -> Vector3 {
        Vector3 { x, y, z }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Quaternion {
    pub const IDENTITY: Quaternion = Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };
    /// From MuJoCo's `[w, x, y, z]`.
    pub fn from_mujoco([w, x, y, z]: [f64; 4]) -> Quaternion {
        Quaternion { x, y, z, w }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Pose {
    pub position: Vector3,
    pub orientation: Quaternion,
}

impl Pose {
    pub fn at(position: [f64; 3]) -> Pose {
        Pose {
            position: Vector3::new(position),
            orientation: Quaternion::IDENTITY,
        }
    }
}

/// RGBA in `[0, 1]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Color {
    pub r: f64,
    pub g: f64,
    pub b: f64,
    pub a: f64,
}

impl Color {
    pub const fn rgb(r: f64, g: f64, b: f64) -> Color {
        Color { r, g, b, a: 1.0 }
    }
}

/// `foxglove.FrameTransform`: `child_frame_id`'s pose in `parent_frame_id`.
#[derive(Debug, Clone, Serialize)]
pub struct FrameTransform<'a> {
    pub timestamp: Time,
    pub parent_frame_id: &'a str,
    pub child_frame_id: &'a str,
    pub translation: Vector3,
    pub rotation: Quaternion,
}

/// `foxglove.FrameTransforms`.
#[derive(Debug, Clone, Serialize)]
pub struct FrameTransforms<'a> {
    pub transforms: Vec<FrameTransform<'a>>,
}

/// The element type of the arrays we always leave empty (no value exists).
#[derive(Debug, Clone, Serialize)]
pub enum Unused {}

/// `foxglove.SceneUpdate`.
#[derive(Debug, Clone, Serialize)]
pub struct SceneUpdate {
    pub deletions: Vec<Unused>,
    pub entities: Vec<SceneEntity>,
}

/// `foxglove.SceneEntity`: primitives drawn in the frame `frame_id`.
#[derive(Debug, Clone, Serialize)]
pub struct SceneEntity {
    pub timestamp: Time,
    pub frame_id: String,
    pub id: String,
    /// Zero: visible until replaced.
    pub lifetime: Time,
    /// Follow `frame_id` as its transform changes.
    pub frame_locked: bool,
    pub metadata: Vec<KeyValuePair>,
    pub arrows: Vec<Unused>,
    pub cubes: Vec<CubePrimitive>,
    pub spheres: Vec<SpherePrimitive>,
    pub cylinders: Vec<CylinderPrimitive>,
    pub lines: Vec<Unused>,
    pub triangles: Vec<TriangleListPrimitive>,
    pub texts: Vec<Unused>,
    pub models: Vec<Unused>,
}

impl SceneEntity {
    /// An entity with no primitives yet, visible until replaced.
    pub fn new(timestamp: Time, frame_id: &str, id: &str, frame_locked: bool) -> SceneEntity {
        SceneEntity {
            timestamp,
            frame_id: frame_id.to_string(),
            id: id.to_string(),
            lifetime: Time::ZERO,
            frame_locked,
            metadata: Vec::new(),
            arrows: Vec::new(),
            cubes: Vec::new(),
            spheres: Vec::new(),
            cylinders: Vec::new(),
            lines: Vec::new(),
            triangles: Vec::new(),
            texts: Vec::new(),
            models: Vec::new(),
        }
    }

    /// Number of primitives of every kind.
    pub fn primitives(&self) -> usize {
        self.cubes.len() + self.spheres.len() + self.cylinders.len() + self.triangles.len()
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct KeyValuePair {
    pub key: String,
    pub value: String,
}

/// A box: `size` is its full extent along each axis.
#[derive(Debug, Clone, Serialize)]
pub struct CubePrimitive {
    pub pose: Pose,
    pub size: Vector3,
    pub color: Color,
}

/// A sphere or ellipsoid: `size` is its diameter along each axis.
#[derive(Debug, Clone, Serialize)]
pub struct SpherePrimitive {
    pub pose: Pose,
    pub size: Vector3,
    pub color: Color,
}

/// A cylinder along its pose's z axis; `size` is its bounding box.
#[derive(Debug, Clone, Serialize)]
pub struct CylinderPrimitive {
    pub pose: Pose,
    pub size: Vector3,
    pub bottom_scale: f64,
    pub top_scale: f64,
    pub color: Color,
}

/// Indexed triangles with per-vertex colors.
#[derive(Debug, Clone, Serialize)]
pub struct TriangleListPrimitive {
    pub pose: Pose,
    pub points: Vec<Vector3>,
    pub color: Color,
    pub colors: Vec<Color>,
    pub indices: Vec<u32>,
}

// --- JSON Schema text ------------------------------------------------------------

fn number(description: &str) -> Value {
    json!({"type": "number", "description": description})
}

fn time(title: &str, description: &str) -> Value {
    let sec = if title == "time" {
        json!({"type": "integer", "minimum": 0})
    } else {
        json!({"type": "integer"})
    };
    json!({
        "type": "object",
        "title": title,
        "description": description,
        "properties": {
            "sec": sec,
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
        }
    })
}

fn object(title: &str, description: &str, properties: Value) -> Value {
    json!({"title": title, "description": description, "type": "object", "properties": properties})
}

fn array(items: Value, description: &str) -> Value {
    json!({"type": "array", "items": items, "description": description})
}

fn vector3(description: &str) -> Value {
    object(
        "foxglove.Vector3",
        description,
        json!({"x": number("x coordinate length"), "y": number("y coordinate length"), "z": number("z coordinate length")}),
    )
}

fn point3(description: &str) -> Value {
    object(
        "foxglove.Point3",
        description,
        json!({"x": number("x coordinate position"), "y": number("y coordinate position"), "z": number("z coordinate position")}),
    )
}

fn quaternion(description: &str) -> Value {
    object(
        "foxglove.Quaternion",
        description,
        json!({"x": number("x value"), "y": number("y value"), "z": number("z value"), "w": number("w value")}),
    )
}

fn pose(description: &str) -> Value {
    object(
        "foxglove.Pose",
        description,
        json!({
            "position": vector3("Point denoting position in 3D space"),
            "orientation": quaternion("Quaternion denoting orientation in 3D space"),
        }),
    )
}

fn color(description: &str) -> Value {
    object(
        "foxglove.Color",
        description,
        json!({
            "r": number("Red value between 0 and 1"),
            "g": number("Green value between 0 and 1"),
            "b": number("Blue value between 0 and 1"),
            "a": number("Alpha value between 0 and 1"),
        }),
    )
}

fn string(description: &str) -> Value {
    json!({"type": "string", "description": description})
}

fn boolean(description: &str) -> Value {
    json!({"type": "boolean", "description": description})
}

fn enumeration(title: &str, description: &str, values: &[(&str, u32, &str)]) -> Value {
    let one_of: Vec<Value> = values
        .iter()
        .map(|(name, v, d)| json!({"title": name, "const": v, "description": d}))
        .collect();
    json!({"title": title, "description": description, "oneOf": one_of})
}

/// The whole schema document of a message: `title` is the schema's name.
fn document(title: &str, description: &str, properties: Value) -> Vec<u8> {
    let mut v = object(title, description, properties);
    v["$comment"] = json!("Written by dreampolicy from Foxglove's schema reference");
    serde_json::to_vec_pretty(&v).expect("a JSON value serializes")
}

/// JSON Schema of `foxglove.FrameTransforms`.
pub fn frame_transforms_schema() -> Vec<u8> {
    let transform = object(
        "foxglove.FrameTransform",
        "A transform between two reference frames in 3D space",
        json!({
            "timestamp": time("time", "Timestamp of transform"),
            "parent_frame_id": string("Name of the parent frame"),
            "child_frame_id": string("Name of the child frame"),
            "translation": vector3("Translation component of the transform"),
            "rotation": quaternion("Rotation component of the transform"),
        }),
    );
    document(
        FRAME_TRANSFORMS,
        "An array of FrameTransform messages",
        json!({"transforms": array(transform, "Array of transforms")}),
    )
}

/// JSON Schema of `foxglove.SceneUpdate` (every primitive of `foxglove.SceneEntity`).
pub fn scene_update_schema() -> Vec<u8> {
    let deletion = object(
        "foxglove.SceneEntityDeletion",
        "Command to remove previously published entities",
        json!({
            "timestamp": time("time", "Timestamp of the deletion. Only matching entities earlier than this timestamp will be deleted."),
            "type": enumeration("foxglove.SceneEntityDeletionType", "Type of deletion action to perform", &[
                ("MATCHING_ID", 0, "Delete the existing entity on the same topic that has the provided `id`"),
                ("ALL", 1, "Delete all existing entities on the same topic"),
            ]),
            "id": string("Identifier which must match if `type` is `MATCHING_ID`."),
        }),
    );
    let arrow = object(
        "foxglove.ArrowPrimitive",
        "A primitive representing an arrow",
        json!({
            "pose": pose("Position of the arrow's tail and orientation of the arrow. Identity orientation means the arrow points in the +x direction."),
            "shaft_length": number("Length of the arrow shaft"),
            "shaft_diameter": number("Diameter of the arrow shaft"),
            "head_length": number("Length of the arrow head"),
            "head_diameter": number("Diameter of the arrow head"),
            "color": color("Color of the arrow"),
        }),
    );
    let cube = object(
        "foxglove.CubePrimitive",
        "A primitive representing a cube or rectangular prism",
        json!({
            "pose": pose("Position of the center of the cube and orientation of the cube"),
            "size": vector3("Size of the cube along each axis"),
            "color": color("Color of the cube"),
        }),
    );
    let sphere = object(
        "foxglove.SpherePrimitive",
        "A primitive representing a sphere or ellipsoid",
        json!({
            "pose": pose("Position of the center of the sphere and orientation of the sphere"),
            "size": vector3("Size (diameter) of the sphere along each axis"),
            "color": color("Color of the sphere"),
        }),
    );
    let cylinder = object(
        "foxglove.CylinderPrimitive",
        "A primitive representing a cylinder, elliptic cylinder, or truncated cone",
        json!({
            "pose": pose("Position of the center of the cylinder and orientation of the cylinder. The flat face(s) are perpendicular to the z-axis."),
            "size": vector3("Size of the cylinder's bounding box"),
            "bottom_scale": number("0-1, ratio of the diameter of the cylinder's bottom face (min z) to the bottom of the bounding box"),
            "top_scale": number("0-1, ratio of the diameter of the cylinder's top face (max z) to the top of the bounding box"),
            "color": color("Color of the cylinder"),
        }),
    );
    let indices = array(
        json!({"type": "integer", "minimum": 0}),
        "Indices into the `points` and `colors` attribute arrays, which can be used to avoid duplicating attribute data.",
    );
    let line = object(
        "foxglove.LinePrimitive",
        "A primitive representing a series of points connected by lines",
        json!({
            "type": enumeration("foxglove.LineType", "Drawing primitive to use for lines", &[
                ("LINE_STRIP", 0, "Connected line segments: 0-1, 1-2, ..., (n-1)-n"),
                ("LINE_LOOP", 1, "Closed polygon: 0-1, 1-2, ..., (n-1)-n, n-0"),
                ("LINE_LIST", 2, "Individual line segments: 0-1, 2-3, 4-5, ..."),
            ]),
            "pose": pose("Origin of lines relative to reference frame"),
            "thickness": number("Line thickness"),
            "scale_invariant": boolean("Indicates whether `thickness` is a fixed size in screen pixels (true), or specified in world coordinates and scales with distance from the camera (false)"),
            "points": array(point3("A point representing a position in 3D space"), "Points along the line"),
            "color": color("Solid color to use for the whole line. Ignored if `colors` is non-empty."),
            "colors": array(color("A color in RGBA format"), "Per-point colors (if specified, must have the same length as `points`)."),
            "indices": indices.clone(),
        }),
    );
    let triangles = object(
        "foxglove.TriangleListPrimitive",
        "A primitive representing a set of triangles or a surface tiled by triangles",
        json!({
            "pose": pose("Origin of triangles relative to reference frame"),
            "points": array(point3("A point representing a position in 3D space"), "Vertices to use for triangles, interpreted as a list of triples (0-1-2, 3-4-5, ...)"),
            "color": color("Solid color to use for the whole shape. Ignored if `colors` is non-empty."),
            "colors": array(color("A color in RGBA format"), "Per-vertex colors (if specified, must have the same length as `points`)."),
            "indices": indices,
        }),
    );
    let text = object(
        "foxglove.TextPrimitive",
        "A primitive representing a text label",
        json!({
            "pose": pose("Position of the center of the text box and orientation of the text. Identity orientation means the text is oriented in the xy-plane and flows from -x to +x."),
            "billboard": boolean("Whether the text should respect `pose.orientation` (false) or always face the camera (true)"),
            "font_size": number("Font size (height of one line of text)"),
            "scale_invariant": boolean("Indicates whether `font_size` is a fixed size in screen pixels (true), or specified in world coordinates and scales with distance from the camera (false)"),
            "color": color("Color of the text"),
            "text": string("Text"),
        }),
    );
    let model = object(
        "foxglove.ModelPrimitive",
        "A primitive representing a 3D model file loaded from an external URL or embedded data",
        json!({
            "pose": pose("Origin of model relative to reference frame"),
            "scale": vector3("Scale factor to apply to the model along each axis"),
            "color": color("Solid color to use for the whole model if `override_color` is true."),
            "override_color": boolean("Whether to use the color specified in `color` instead of any materials embedded in the original model."),
            "url": string("URL pointing to model file. One of `url` or `data` should be provided."),
            "media_type": string("[Media type](https://developer.mozilla.org/en-US/docs/Web/HTTP/Basics_of_HTTP/MIME_types) of embedded model (e.g. `model/gltf-binary`). Required if `data` is provided instead of `url`. Overrides the inferred media type if `url` is provided."),
            "data": {"type": "string", "contentEncoding": "base64", "description": "Embedded model. One of `url` or `data` should be provided. If `data` is provided, `media_type` must be set to indicate the type of the data."},
        }),
    );
    let entity = object(
        "foxglove.SceneEntity",
        "A visual element in a 3D scene. An entity may be composed of multiple primitives which all share the same frame of reference.",
        json!({
            "timestamp": time("time", "Timestamp of the entity"),
            "frame_id": string("Frame of reference"),
            "id": string("Identifier for the entity. A entity will replace any prior entity on the same topic with the same `id`."),
            "lifetime": time("duration", "Length of time (relative to `timestamp`) after which the entity should be automatically removed. Zero value indicates the entity should remain visible until it is replaced or deleted."),
            "frame_locked": boolean("Whether the entity should keep its location in the fixed frame (false) or follow the frame specified in `frame_id` as it moves relative to the fixed frame (true)"),
            "metadata": array(object("foxglove.KeyValuePair", "A key with its associated value", json!({"key": string("Key"), "value": string("Value")})), "Additional user-provided metadata associated with the entity. Keys must be unique."),
            "arrows": array(arrow, "Arrow primitives"),
            "cubes": array(cube, "Cube primitives"),
            "spheres": array(sphere, "Sphere primitives"),
            "cylinders": array(cylinder, "Cylinder primitives"),
            "lines": array(line, "Line primitives"),
            "triangles": array(triangles, "Triangle list primitives"),
            "texts": array(text, "Text primitives"),
            "models": array(model, "Model primitives"),
        }),
    );
    document(
        SCENE_UPDATE,
        "An update to the entities displayed in a 3D scene",
        json!({
            "deletions": array(deletion, "Scene entities to delete"),
            "entities": array(entity, "Scene entities to add or replace"),
        }),
    )
}

/// JSON Schema of one of our plain messages: an object of numbers (`fields`:
/// name, description) plus, when `terms` is given, an object `terms` of
/// numbers named by it.
pub fn plain_schema(
    title: &str,
    description: &str,
    fields: &[(&str, &str)],
    terms: Option<&[&str]>,
) -> Vec<u8> {
    let mut props = serde_json::Map::new();
    for (name, d) in fields {
        props.insert((*name).to_string(), number(d));
    }
    if let Some(names) = terms {
        let t: serde_json::Map<String, Value> = names
            .iter()
            .map(|n| ((*n).to_string(), number("weight x term x dt")))
            .collect();
        props.insert(
            "terms".into(),
            json!({"type": "object", "description": "Reward terms of this step (weighted, x dt)", "properties": t}),
        );
    }
    document(title, description, Value::Object(props))
}
