//! `Model`: an owned, loaded MuJoCo model (`mjModel`), shared read-only across threads.
use std::ffi::{c_char, CStr, CString};
use std::path::{Path, PathBuf};
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU64, Ordering};

use mujoco_sys as sys;

use super::{handlers, SimError};

/// Object kinds for name lookups (a subset of `mjtObj`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjType {
    Body,
    Joint,
    Geom,
    Site,
    Actuator,
    Sensor,
    Hfield,
    Key,
}

impl ObjType {
    fn raw(self) -> i32 {
        (match self {
            ObjType::Body => sys::mjOBJ_BODY,
            ObjType::Joint => sys::mjOBJ_JOINT,
            ObjType::Geom => sys::mjOBJ_GEOM,
            ObjType::Site => sys::mjOBJ_SITE,
            ObjType::Actuator => sys::mjOBJ_ACTUATOR,
            ObjType::Sensor => sys::mjOBJ_SENSOR,
            ObjType::Hfield => sys::mjOBJ_HFIELD,
            ObjType::Key => sys::mjOBJ_KEY,
        }) as i32
    }

    /// Lower-case name used in error messages.
    pub fn label(self) -> &'static str {
        match self {
            ObjType::Body => "body",
            ObjType::Joint => "joint",
            ObjType::Geom => "geom",
            ObjType::Site => "site",
            ObjType::Actuator => "actuator",
            ObjType::Sensor => "sensor",
            ObjType::Hfield => "hfield",
            ObjType::Key => "keyframe",
        }
    }
}

/// Size and placement of one heightfield asset (`hfield_size` is MuJoCo's
/// `(radius_x, radius_y, elevation_z, base_z)`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HfieldInfo {
    pub nrow: usize,
    pub ncol: usize,
    pub size: [f64; 4],
}

/// A compiled MuJoCo model. Owns its `mjModel` and frees it on drop.
///
/// MuJoCo only reads the model during simulation, so one `Model` is shared by
/// every thread through `Arc<Model>` with one [`super::Data`] per thread.
/// Mutation (heightfield upload, armature, gains) needs `&mut Model`, i.e. happens
/// before the model is shared.
pub struct Model {
    ptr: NonNull<sys::mjModel>,
    source: String,
}

// SAFETY: an mjModel is plain memory owned by this struct. MuJoCo's simulation
// functions take `const mjModel*` and never write to it, so shared references
// may be used from several threads at once; mutation requires `&mut self`.
unsafe impl Send for Model {}
// SAFETY: see above: `&Model` only exposes reads.
unsafe impl Sync for Model {}

impl Drop for Model {
    fn drop(&mut self) {
        // SAFETY: the pointer came from mj_loadXML/mj_copyModel and is freed once.
        unsafe { sys::mj_deleteModel(self.ptr.as_ptr()) }
    }
}

impl std::fmt::Debug for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Model")
            .field("source", &self.source)
            .field("nq", &self.nq())
            .field("nv", &self.nv())
            .field("nu", &self.nu())
            .finish()
    }
}

impl Clone for Model {
    fn clone(&self) -> Self {
        // SAFETY: mj_copyModel with dest = NULL allocates a deep copy of a valid model.
        let ptr = unsafe { sys::mj_copyModel(std::ptr::null_mut(), self.ptr.as_ptr()) };
        Model {
            ptr: NonNull::new(ptr).expect("mj_copyModel: out of memory"),
            source: self.source.clone(),
        }
    }
}

const ERR_LEN: usize = 1000;

/// Slice over MuJoCo-owned memory; empty for a NULL pointer or zero length.
///
/// # Safety
/// `ptr` must point to at least `len` valid `T` that outlive the returned slice.
pub(crate) unsafe fn slice<'a, T>(ptr: *const T, len: usize) -> &'a [T] {
    if ptr.is_null() || len == 0 {
        &[]
    } else {
        // SAFETY: guaranteed by the caller.
        unsafe { std::slice::from_raw_parts(ptr, len) }
    }
}

/// Mutable twin of [`slice`].
///
/// # Safety
/// As for [`slice`], plus exclusive access for the returned lifetime.
pub(crate) unsafe fn slice_mut<'a, T>(ptr: *mut T, len: usize) -> &'a mut [T] {
    if ptr.is_null() || len == 0 {
        &mut []
    } else {
        // SAFETY: guaranteed by the caller.
        unsafe { std::slice::from_raw_parts_mut(ptr, len) }
    }
}

fn n(x: i32) -> usize {
    x.max(0) as usize
}

impl Model {
    /// Load an MJCF (or MJB-free XML) file. A missing file, a malformed XML or a
    /// missing mesh each come back as a typed error with MuJoCo's text.
    pub fn from_xml_path(path: impl AsRef<Path>) -> Result<Model, SimError> {
        handlers::install();
        let path = path.as_ref();
        if !path.is_file() {
            return Err(SimError::NotFound(path.to_path_buf()));
        }
        let cpath =
            CString::new(path.to_string_lossy().as_bytes()).map_err(|_| SimError::Load {
                path: path.to_path_buf(),
                message: "path contains a NUL byte".into(),
            })?;
        let mut err = vec![0 as c_char; ERR_LEN];
        // SAFETY: valid C string, NULL VFS, error buffer of ERR_LEN bytes.
        let ptr = unsafe {
            sys::mj_loadXML(
                cpath.as_ptr(),
                std::ptr::null(),
                err.as_mut_ptr(),
                ERR_LEN as i32,
            )
        };
        match NonNull::new(ptr) {
            Some(ptr) => Ok(Model {
                ptr,
                source: path.display().to_string(),
            }),
            None => {
                // SAFETY: MuJoCo NUL-terminates the buffer it was given.
                let msg = unsafe { CStr::from_ptr(err.as_ptr()) }
                    .to_string_lossy()
                    .trim()
                    .to_string();
                Err(SimError::Load {
                    path: path.to_path_buf(),
                    message: if msg.is_empty() {
                        "unknown error (MuJoCo gave no message)".into()
                    } else {
                        msg
                    },
                })
            }
        }
    }

    /// Load a model from an XML string. MuJoCo reads files, so the text is written
    /// to a temporary file first; relative `file=` references resolve against
    /// `base_dir` (the temporary file is created there), so pass the directory the
    /// XML would live in. Errors name `label` rather than the temporary file.
    pub fn from_xml_str(xml: &str, base_dir: &Path, label: &str) -> Result<Model, SimError> {
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let tmp = base_dir.join(format!(
            ".dreampolicy-{}-{}.xml",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::write(&tmp, xml).map_err(|source| SimError::Io {
            path: tmp.clone(),
            source,
        })?;
        let result = Model::from_xml_path(&tmp);
        let _ = std::fs::remove_file(&tmp);
        match result {
            Ok(mut m) => {
                m.source = label.to_string();
                Ok(m)
            }
            Err(SimError::Load { message, .. }) => Err(SimError::Load {
                path: PathBuf::from(label),
                message,
            }),
            Err(e) => Err(e),
        }
    }

    /// Where the model came from (path or label), for messages.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The raw `mjModel` (read-only).
    pub fn raw(&self) -> &sys::mjModel {
        // SAFETY: the pointer is valid for the lifetime of self.
        unsafe { self.ptr.as_ref() }
    }

    /// The raw `mjModel`, mutable. Changing sizes or pointers is undefined behaviour;
    /// changing parameter values (gains, friction, masses) is how MuJoCo is meant to be used.
    pub fn raw_mut(&mut self) -> &mut sys::mjModel {
        // SAFETY: the pointer is valid and we hold &mut self.
        unsafe { self.ptr.as_mut() }
    }

    pub(crate) fn as_ptr(&self) -> *const sys::mjModel {
        self.ptr.as_ptr()
    }

    pub fn nq(&self) -> usize {
        n(self.raw().nq)
    }
    pub fn nv(&self) -> usize {
        n(self.raw().nv)
    }
    pub fn nu(&self) -> usize {
        n(self.raw().nu)
    }
    pub fn na(&self) -> usize {
        n(self.raw().na)
    }
    pub fn nbody(&self) -> usize {
        n(self.raw().nbody)
    }
    pub fn njnt(&self) -> usize {
        n(self.raw().njnt)
    }
    pub fn ngeom(&self) -> usize {
        n(self.raw().ngeom)
    }
    pub fn nsite(&self) -> usize {
        n(self.raw().nsite)
    }
    pub fn nsensor(&self) -> usize {
        n(self.raw().nsensor)
    }
    pub fn nsensordata(&self) -> usize {
        n(self.raw().nsensordata)
    }
    pub fn nkey(&self) -> usize {
        n(self.raw().nkey)
    }
    pub fn nhfield(&self) -> usize {
        n(self.raw().nhfield)
    }
    /// Physics timestep in seconds.
    pub fn timestep(&self) -> f64 {
        self.raw().opt.timestep
    }
    pub fn set_timestep(&mut self, dt: f64) {
        self.raw_mut().opt.timestep = dt;
    }

    /// Id of the named object, if it exists.
    pub fn name2id(&self, obj: ObjType, name: &str) -> Option<usize> {
        let cname = CString::new(name).ok()?;
        // SAFETY: valid model and C string.
        let id = unsafe { sys::mj_name2id(self.as_ptr(), obj.raw(), cname.as_ptr()) };
        (id >= 0).then_some(id as usize)
    }

    /// Id of the named object, or a `SimError::UnknownName` that says which.
    pub fn id(&self, obj: ObjType, name: &str) -> Result<usize, SimError> {
        self.name2id(obj, name)
            .ok_or_else(|| SimError::UnknownName {
                kind: obj.label(),
                name: name.to_string(),
                model: self.source.clone(),
            })
    }

    /// Name of the object with this id (None for an unnamed or out-of-range id).
    pub fn id2name(&self, obj: ObjType, id: usize) -> Option<&str> {
        // SAFETY: valid model; MuJoCo bounds-checks the id and returns NULL if bad.
        let p = unsafe { sys::mj_id2name(self.as_ptr(), obj.raw(), id as i32) };
        if p.is_null() {
            return None;
        }
        // SAFETY: names live in the model's name buffer for the model's lifetime.
        unsafe { CStr::from_ptr(p) }.to_str().ok()
    }

    // --- per-object arrays (read) -----------------------------------------------

    pub fn jnt_qposadr(&self) -> &[i32] {
        // SAFETY: njnt ints.
        unsafe { slice(self.raw().jnt_qposadr, self.njnt()) }
    }
    pub fn jnt_dofadr(&self) -> &[i32] {
        // SAFETY: njnt ints.
        unsafe { slice(self.raw().jnt_dofadr, self.njnt()) }
    }
    pub fn jnt_type(&self) -> &[i32] {
        // SAFETY: njnt ints.
        unsafe { slice(self.raw().jnt_type, self.njnt()) }
    }
    /// Joint ranges as `[lo, hi]`.
    pub fn jnt_range(&self) -> &[[f64; 2]] {
        // SAFETY: 2*njnt doubles, laid out as njnt pairs.
        unsafe { slice(self.raw().jnt_range as *const [f64; 2], self.njnt()) }
    }
    /// Actuator transmission targets `[id, id2]` (joint id for joint transmissions).
    pub fn actuator_trnid(&self) -> &[[i32; 2]] {
        // SAFETY: 2*nu ints.
        unsafe { slice(self.raw().actuator_trnid as *const [i32; 2], self.nu()) }
    }
    pub fn actuator_forcerange(&self) -> &[[f64; 2]] {
        // SAFETY: 2*nu doubles.
        unsafe { slice(self.raw().actuator_forcerange as *const [f64; 2], self.nu()) }
    }
    /// Gain parameters, `mjNGAIN` per actuator.
    pub fn actuator_gainprm(&self) -> &[f64] {
        // SAFETY: mjNGAIN*nu doubles.
        unsafe {
            slice(
                self.raw().actuator_gainprm,
                self.nu() * sys::mjNGAIN as usize,
            )
        }
    }
    /// Bias parameters, `mjNBIAS` per actuator.
    pub fn actuator_biasprm(&self) -> &[f64] {
        // SAFETY: mjNBIAS*nu doubles.
        unsafe {
            slice(
                self.raw().actuator_biasprm,
                self.nu() * sys::mjNBIAS as usize,
            )
        }
    }
    pub fn actuator_gainprm_mut(&mut self) -> &mut [f64] {
        let len = self.nu() * sys::mjNGAIN as usize;
        // SAFETY: mjNGAIN*nu doubles, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().actuator_gainprm, len) }
    }
    pub fn actuator_biasprm_mut(&mut self) -> &mut [f64] {
        let len = self.nu() * sys::mjNBIAS as usize;
        // SAFETY: mjNBIAS*nu doubles, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().actuator_biasprm, len) }
    }
    pub fn dof_armature(&self) -> &[f64] {
        // SAFETY: nv doubles.
        unsafe { slice(self.raw().dof_armature, self.nv()) }
    }
    pub fn dof_armature_mut(&mut self) -> &mut [f64] {
        let nv = self.nv();
        // SAFETY: nv doubles, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().dof_armature, nv) }
    }
    pub fn body_mass(&self) -> &[f64] {
        // SAFETY: nbody doubles.
        unsafe { slice(self.raw().body_mass, self.nbody()) }
    }
    pub fn body_mass_mut(&mut self) -> &mut [f64] {
        let nb = self.nbody();
        // SAFETY: nbody doubles, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().body_mass, nb) }
    }
    pub fn body_parentid(&self) -> &[i32] {
        // SAFETY: nbody ints.
        unsafe { slice(self.raw().body_parentid, self.nbody()) }
    }
    /// Position of each body's frame in its parent's frame.
    pub fn body_pos(&self) -> &[[f64; 3]] {
        // SAFETY: 3*nbody doubles.
        unsafe { slice(self.raw().body_pos as *const [f64; 3], self.nbody()) }
    }
    /// Total mass of the subtree rooted at each body.
    pub fn body_subtreemass(&self) -> &[f64] {
        // SAFETY: nbody doubles.
        unsafe { slice(self.raw().body_subtreemass, self.nbody()) }
    }
    pub fn geom_bodyid(&self) -> &[i32] {
        // SAFETY: ngeom ints.
        unsafe { slice(self.raw().geom_bodyid, self.ngeom()) }
    }
    pub fn geom_type(&self) -> &[i32] {
        // SAFETY: ngeom ints.
        unsafe { slice(self.raw().geom_type, self.ngeom()) }
    }
    pub fn geom_dataid(&self) -> &[i32] {
        // SAFETY: ngeom ints.
        unsafe { slice(self.raw().geom_dataid, self.ngeom()) }
    }
    /// Geom sizes: radius, half-length or half-extents, by geom type (MuJoCo's `geom_size`).
    pub fn geom_size(&self) -> &[[f64; 3]] {
        // SAFETY: 3*ngeom doubles.
        unsafe { slice(self.raw().geom_size as *const [f64; 3], self.ngeom()) }
    }
    pub fn geom_pos(&self) -> &[[f64; 3]] {
        // SAFETY: 3*ngeom doubles.
        unsafe { slice(self.raw().geom_pos as *const [f64; 3], self.ngeom()) }
    }
    pub fn geom_quat(&self) -> &[[f64; 4]] {
        // SAFETY: 4*ngeom doubles.
        unsafe { slice(self.raw().geom_quat as *const [f64; 4], self.ngeom()) }
    }
    /// Sliding, torsional and rolling friction per geom.
    pub fn geom_friction_mut(&mut self) -> &mut [[f64; 3]] {
        let ng = self.ngeom();
        // SAFETY: 3*ngeom doubles, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().geom_friction as *mut [f64; 3], ng) }
    }
    pub fn geom_friction(&self) -> &[[f64; 3]] {
        // SAFETY: 3*ngeom doubles.
        unsafe { slice(self.raw().geom_friction as *const [f64; 3], self.ngeom()) }
    }
    pub fn geom_contype_mut(&mut self) -> &mut [i32] {
        let ng = self.ngeom();
        // SAFETY: ngeom ints, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().geom_contype, ng) }
    }
    /// Contact dimensionality per geom (1 frictionless, 3 with sliding friction, ...).
    pub fn geom_condim_mut(&mut self) -> &mut [i32] {
        let ng = self.ngeom();
        // SAFETY: ngeom ints, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().geom_condim, ng) }
    }
    pub fn geom_conaffinity_mut(&mut self) -> &mut [i32] {
        let ng = self.ngeom();
        // SAFETY: ngeom ints, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().geom_conaffinity, ng) }
    }
    pub fn geom_conaffinity(&self) -> &[i32] {
        // SAFETY: ngeom ints.
        unsafe { slice(self.raw().geom_conaffinity, self.ngeom()) }
    }
    pub fn geom_contype(&self) -> &[i32] {
        // SAFETY: ngeom ints.
        unsafe { slice(self.raw().geom_contype, self.ngeom()) }
    }
    pub fn sensor_adr(&self) -> &[i32] {
        // SAFETY: nsensor ints.
        unsafe { slice(self.raw().sensor_adr, self.nsensor()) }
    }
    pub fn sensor_dim(&self) -> &[i32] {
        // SAFETY: nsensor ints.
        unsafe { slice(self.raw().sensor_dim, self.nsensor()) }
    }
    /// qpos stored in keyframe `key`.
    pub fn key_qpos(&self, key: usize) -> Result<&[f64], SimError> {
        self.check_key(key)?;
        let nq = self.nq();
        // SAFETY: nkey*nq doubles and key < nkey.
        Ok(unsafe { slice(self.raw().key_qpos.add(key * nq), nq) })
    }
    /// ctrl stored in keyframe `key`.
    pub fn key_ctrl(&self, key: usize) -> Result<&[f64], SimError> {
        self.check_key(key)?;
        let nu = self.nu();
        // SAFETY: nkey*nu doubles and key < nkey.
        Ok(unsafe { slice(self.raw().key_ctrl.add(key * nu), nu) })
    }

    pub(crate) fn check_key(&self, key: usize) -> Result<(), SimError> {
        if key >= self.nkey() {
            return Err(SimError::BadIndex {
                kind: "keyframe",
                index: key,
                count: self.nkey(),
            });
        }
        Ok(())
    }

    /// Recompute derived constants (`mj_setConst`: subtree masses, actuator
    /// lengths at qpos0, ...) after changing masses or other parameters.
    pub fn set_const(&mut self) -> Result<(), SimError> {
        // SAFETY: a temporary mjData for this model, freed before returning.
        unsafe {
            let d = sys::mj_makeData(self.as_ptr());
            if d.is_null() {
                return Err(SimError::MakeData(self.source.clone()));
            }
            sys::mj_setConst(self.ptr.as_ptr(), d);
            sys::mj_deleteData(d);
        }
        Ok(())
    }

    // --- heightfields ----------------------------------------------------------

    /// Dimensions of heightfield `id`.
    pub fn hfield(&self, id: usize) -> Result<HfieldInfo, SimError> {
        if id >= self.nhfield() {
            return Err(SimError::BadIndex {
                kind: "hfield",
                index: id,
                count: self.nhfield(),
            });
        }
        let m = self.raw();
        // SAFETY: id < nhfield; the arrays have nhfield (x4 for size) entries.
        unsafe {
            let s = m.hfield_size.add(4 * id);
            Ok(HfieldInfo {
                nrow: n(*m.hfield_nrow.add(id)),
                ncol: n(*m.hfield_ncol.add(id)),
                size: [*s, *s.add(1), *s.add(2), *s.add(3)],
            })
        }
    }

    /// The normalized elevation data of heightfield `id` (row-major, `nrow x ncol`,
    /// row = y, column = x; world height = value * size[2]).
    pub fn hfield_data(&self, id: usize) -> Result<&[f32], SimError> {
        let info = self.hfield(id)?;
        let m = self.raw();
        // SAFETY: id < nhfield; the data block at hfield_adr[id] holds nrow*ncol floats.
        Ok(unsafe {
            let adr = n(*m.hfield_adr.add(id));
            slice(m.hfield_data.add(adr), info.nrow * info.ncol)
        })
    }

    /// Write elevation data into heightfield `id` of the compiled model. Values are
    /// MuJoCo's normalized heights in `[0, 1]` (world height = value * size[2] above
    /// the geom's frame); anything else is refused, because MuJoCo's collision
    /// bounding box assumes that range. Takes effect at the next collision check;
    /// a renderer would also need `mjr_uploadHField` (we do not render).
    pub fn set_hfield_data(&mut self, id: usize, data: &[f32]) -> Result<(), SimError> {
        let info = self.hfield(id)?;
        if data.len() != info.nrow * info.ncol {
            return Err(SimError::Size {
                what: "heightfield data (nrow * ncol)",
                expected: info.nrow * info.ncol,
                got: data.len(),
            });
        }
        if let Some((i, v)) = data
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && (0.0..=1.0).contains(*v)))
        {
            return Err(SimError::Hfield(format!(
                "value {v} at index {i} is outside MuJoCo's normalized range [0, 1]"
            )));
        }
        let m = self.raw_mut();
        // SAFETY: id < nhfield; the block at hfield_adr[id] holds nrow*ncol floats
        // and we hold &mut self.
        unsafe {
            let adr = n(*m.hfield_adr.add(id));
            slice_mut(m.hfield_data.add(adr), data.len()).copy_from_slice(data);
        }
        Ok(())
    }
}
