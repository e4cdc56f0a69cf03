//! `Data`: one simulation state (`mjData`) bound to a shared [`Model`].
use std::ptr::NonNull;
use std::sync::Arc;

use mujoco_sys as sys;

use super::model::{slice, slice_mut};
use super::{Instability, Model, SimError};

/// Number of MuJoCo warning kinds (`mjNWARNING`).
pub const NUM_WARNINGS: usize = sys::mjNWARNING as usize;

/// Default bound on |qvel| (rad/s or m/s) past which a state counts as blown up.
pub const DEFAULT_MAX_QVEL: f64 = 1.0e3;

/// One contact, as MuJoCo reports it.
pub type Contact = sys::mjContact;

/// Geom ids of a contact, across MuJoCo 2.x (`geom1`, `geom2`) and 3.x (`geom[2]`).
#[inline]
pub fn contact_geoms(c: &Contact) -> (i32, i32) {
    #[cfg(mujoco_v3)]
    {
        (c.geom[0], c.geom[1])
    }
    #[cfg(not(mujoco_v3))]
    {
        (c.geom1, c.geom2)
    }
}

/// The simulation state of one environment. Holds an `Arc<Model>` so it cannot
/// outlive its model; frees its `mjData` on drop. `Send` (one per thread), not `Sync`.
pub struct Data {
    ptr: NonNull<sys::mjData>,
    model: Arc<Model>,
    max_qvel: f64,
    warning_totals: [u64; NUM_WARNINGS],
}

// SAFETY: mjData is plain memory owned by this struct and only touched through
// &self/&mut self; the Model it reads is Sync. Moving it to another thread is fine.
unsafe impl Send for Data {}

impl std::fmt::Debug for Data {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Data")
            .field("model", &self.model.source())
            .field("time", &self.time())
            .finish()
    }
}

impl Drop for Data {
    fn drop(&mut self) {
        // SAFETY: the pointer came from mj_makeData and is freed once.
        unsafe { sys::mj_deleteData(self.ptr.as_ptr()) }
    }
}

impl Data {
    /// Allocate a state for `model` (at qpos0, not yet forwarded).
    pub fn new(model: Arc<Model>) -> Result<Data, SimError> {
        // SAFETY: valid model.
        let ptr = unsafe { sys::mj_makeData(model.as_ptr()) };
        let ptr = NonNull::new(ptr).ok_or_else(|| SimError::MakeData(model.source().into()))?;
        Ok(Data {
            ptr,
            model,
            max_qvel: DEFAULT_MAX_QVEL,
            warning_totals: [0; NUM_WARNINGS],
        })
    }

    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }

    /// The raw pointers, for benchmarks that call `mujoco_sys` directly as a
    /// baseline. Valid while `self` lives; using them is the caller's `unsafe`.
    pub fn as_raw_ptrs(&mut self) -> (*const sys::mjModel, *mut sys::mjData) {
        (self.model.as_ptr(), self.ptr.as_ptr())
    }

    /// The raw `mjData` (read-only).
    pub fn raw(&self) -> &sys::mjData {
        // SAFETY: valid for the lifetime of self.
        unsafe { self.ptr.as_ref() }
    }

    /// The raw `mjData`, mutable (values only: sizes and pointers are MuJoCo's).
    pub fn raw_mut(&mut self) -> &mut sys::mjData {
        // SAFETY: valid, and we hold &mut self.
        unsafe { self.ptr.as_mut() }
    }

    /// Bound on |qvel| used by [`Data::check`].
    pub fn set_max_qvel(&mut self, bound: f64) {
        self.max_qvel = bound;
    }

    /// One physics step (`mj_step`) followed by [`Data::check`].
    #[inline]
    pub fn step(&mut self) -> Result<(), SimError> {
        self.step_unchecked();
        self.check()
    }

    /// `mj_step` alone, for callers that check once after several steps.
    #[inline]
    pub fn step_unchecked(&mut self) {
        // SAFETY: model and data are valid and belong together (Data holds its Arc<Model>).
        unsafe { sys::mj_step(self.model.as_ptr(), self.ptr.as_ptr()) }
    }

    /// `mj_forward`: positions, velocities and accelerations without integrating.
    pub fn forward(&mut self) {
        // SAFETY: as in step_unchecked.
        unsafe { sys::mj_forward(self.model.as_ptr(), self.ptr.as_ptr()) }
    }

    /// `mj_kinematics`: body/geom/site poses from qpos only.
    pub fn kinematics(&mut self) {
        // SAFETY: as in step_unchecked.
        unsafe { sys::mj_kinematics(self.model.as_ptr(), self.ptr.as_ptr()) }
    }

    /// `mj_comPos` then `mj_comVel`: `subtree_com` and the bodies' spatial
    /// velocities `cvel` for the current poses and `qvel` (call
    /// [`Data::kinematics`] first).
    pub fn com_vel(&mut self) {
        // SAFETY: as in step_unchecked.
        unsafe {
            sys::mj_comPos(self.model.as_ptr(), self.ptr.as_ptr());
            sys::mj_comVel(self.model.as_ptr(), self.ptr.as_ptr());
        }
    }

    /// Reset to the model's qpos0 (`mj_resetData`).
    pub fn reset(&mut self) {
        // SAFETY: as in step_unchecked.
        unsafe { sys::mj_resetData(self.model.as_ptr(), self.ptr.as_ptr()) }
    }

    /// Reset to keyframe `key` (`mj_resetDataKeyframe`); a bad index is an error.
    pub fn reset_keyframe(&mut self, key: usize) -> Result<(), SimError> {
        self.model.check_key(key)?;
        // SAFETY: key < nkey, checked above.
        unsafe { sys::mj_resetDataKeyframe(self.model.as_ptr(), self.ptr.as_ptr(), key as i32) }
        Ok(())
    }

    /// Instability check: MuJoCo's bad-qpos/qvel/qacc warnings (MuJoCo has already
    /// reset the state when it raises them), NaN/Inf in qpos/qvel, or |qvel| past the
    /// bound. Every MuJoCo warning is added to [`Data::warning_totals`] and cleared,
    /// so a warning is reported once and never lost.
    #[inline]
    pub fn check(&mut self) -> Result<(), SimError> {
        let time = self.raw().time;
        let mut reason = None;
        {
            // SAFETY: valid, and we hold &mut self; borrowed apart from warning_totals.
            let d = unsafe { self.ptr.as_mut() };
            for (i, w) in d.warning.iter_mut().enumerate() {
                if w.number > 0 {
                    self.warning_totals[i] += w.number as u64;
                    let dof = w.lastinfo;
                    w.number = 0;
                    reason = reason.or(match i as u32 {
                        sys::mjWARN_BADQACC => Some(Instability::BadQacc { dof }),
                        sys::mjWARN_BADQPOS => Some(Instability::BadQpos { dof }),
                        sys::mjWARN_BADQVEL => Some(Instability::BadQvel { dof }),
                        _ => None,
                    });
                }
            }
        }
        if reason.is_none() {
            reason = self.scan_state();
        }
        match reason {
            None => Ok(()),
            Some(reason) => Err(SimError::Unstable { time, reason }),
        }
    }

    fn scan_state(&self) -> Option<Instability> {
        if let Some(i) = self.qpos().iter().position(|v| !v.is_finite()) {
            return Some(Instability::NonFinite {
                field: "qpos",
                index: i,
            });
        }
        for (dof, &v) in self.qvel().iter().enumerate() {
            if !v.is_finite() {
                return Some(Instability::NonFinite {
                    field: "qvel",
                    index: dof,
                });
            }
            if v.abs() > self.max_qvel {
                return Some(Instability::Velocity {
                    dof,
                    value: v,
                    limit: self.max_qvel,
                });
            }
        }
        None
    }

    /// MuJoCo warnings seen by [`Data::check`] since this `Data` was made, per `mjtWarning`.
    pub fn warning_totals(&self) -> &[u64; NUM_WARNINGS] {
        &self.warning_totals
    }

    pub fn time(&self) -> f64 {
        self.raw().time
    }

    pub fn qpos(&self) -> &[f64] {
        // SAFETY: nq doubles owned by this mjData.
        unsafe { slice(self.raw().qpos, self.model.nq()) }
    }
    pub fn qpos_mut(&mut self) -> &mut [f64] {
        let nq = self.model.nq();
        // SAFETY: nq doubles, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().qpos, nq) }
    }
    pub fn qvel(&self) -> &[f64] {
        // SAFETY: nv doubles.
        unsafe { slice(self.raw().qvel, self.model.nv()) }
    }
    pub fn qvel_mut(&mut self) -> &mut [f64] {
        let nv = self.model.nv();
        // SAFETY: nv doubles, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().qvel, nv) }
    }
    pub fn qacc(&self) -> &[f64] {
        // SAFETY: nv doubles.
        unsafe { slice(self.raw().qacc, self.model.nv()) }
    }
    pub fn ctrl(&self) -> &[f64] {
        // SAFETY: nu doubles.
        unsafe { slice(self.raw().ctrl, self.model.nu()) }
    }
    pub fn ctrl_mut(&mut self) -> &mut [f64] {
        let nu = self.model.nu();
        // SAFETY: nu doubles, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().ctrl, nu) }
    }
    pub fn act(&self) -> &[f64] {
        // SAFETY: na doubles.
        unsafe { slice(self.raw().act, self.model.na()) }
    }
    /// Actuator forces after gains, bias and clamping.
    pub fn actuator_force(&self) -> &[f64] {
        // SAFETY: nu doubles.
        unsafe { slice(self.raw().actuator_force, self.model.nu()) }
    }
    /// External force applied per dof (for pushes).
    pub fn qfrc_applied_mut(&mut self) -> &mut [f64] {
        let nv = self.model.nv();
        // SAFETY: nv doubles, exclusive through &mut self.
        unsafe { slice_mut(self.raw_mut().qfrc_applied, nv) }
    }
    pub fn sensordata(&self) -> &[f64] {
        // SAFETY: nsensordata doubles.
        unsafe { slice(self.raw().sensordata, self.model.nsensordata()) }
    }
    /// Body frame positions in world coordinates.
    pub fn xpos(&self) -> &[[f64; 3]] {
        // SAFETY: 3*nbody doubles.
        unsafe { slice(self.raw().xpos as *const [f64; 3], self.model.nbody()) }
    }
    /// Body frame orientations (w, x, y, z).
    pub fn xquat(&self) -> &[[f64; 4]] {
        // SAFETY: 4*nbody doubles.
        unsafe { slice(self.raw().xquat as *const [f64; 4], self.model.nbody()) }
    }
    /// Body frame rotation matrices, row-major.
    pub fn xmat(&self) -> &[[f64; 9]] {
        // SAFETY: 9*nbody doubles.
        unsafe { slice(self.raw().xmat as *const [f64; 9], self.model.nbody()) }
    }
    /// Body centre-of-mass positions.
    pub fn xipos(&self) -> &[[f64; 3]] {
        // SAFETY: 3*nbody doubles.
        unsafe { slice(self.raw().xipos as *const [f64; 3], self.model.nbody()) }
    }
    /// Body spatial velocities `[rot(3), lin(3)]` about the subtree COM, world-aligned.
    pub fn cvel(&self) -> &[[f64; 6]] {
        // SAFETY: 6*nbody doubles.
        unsafe { slice(self.raw().cvel as *const [f64; 6], self.model.nbody()) }
    }
    /// External (contact) wrenches per body `[torque(3), force(3)]`, valid after
    /// `mj_rnePostConstraint` (computed by mj_step only when a sensor needs it;
    /// [`Data::rne_post_constraint`] computes it on demand).
    pub fn cfrc_ext(&self) -> &[[f64; 6]] {
        // SAFETY: 6*nbody doubles.
        unsafe { slice(self.raw().cfrc_ext as *const [f64; 6], self.model.nbody()) }
    }
    /// Compute `cfrc_ext`/`cacc`/`cfrc_int` for the current state.
    pub fn rne_post_constraint(&mut self) {
        // SAFETY: as in step_unchecked.
        unsafe { sys::mj_rnePostConstraint(self.model.as_ptr(), self.ptr.as_ptr()) }
    }
    pub fn subtree_com(&self) -> &[[f64; 3]] {
        // SAFETY: 3*nbody doubles.
        unsafe {
            slice(
                self.raw().subtree_com as *const [f64; 3],
                self.model.nbody(),
            )
        }
    }
    pub fn geom_xpos(&self) -> &[[f64; 3]] {
        // SAFETY: 3*ngeom doubles.
        unsafe { slice(self.raw().geom_xpos as *const [f64; 3], self.model.ngeom()) }
    }
    pub fn site_xpos(&self) -> &[[f64; 3]] {
        // SAFETY: 3*nsite doubles.
        unsafe { slice(self.raw().site_xpos as *const [f64; 3], self.model.nsite()) }
    }
    /// The active contacts of the last collision pass.
    pub fn contacts(&self) -> &[Contact] {
        let d = self.raw();
        // SAFETY: MuJoCo keeps ncon valid contacts at d->contact.
        unsafe { slice(d.contact, d.ncon.max(0) as usize) }
    }
    /// Contact wrench of contact `i` in the contact frame `[normal, tangent1,
    /// tangent2, torques...]`; None for an index out of range.
    pub fn contact_force(&self, i: usize) -> Option<[f64; 6]> {
        if i >= self.contacts().len() {
            return None;
        }
        let mut out = [0.0; 6];
        // SAFETY: i < ncon and out has 6 doubles.
        unsafe {
            sys::mj_contactForce(
                self.model.as_ptr(),
                self.ptr.as_ptr(),
                i as i32,
                out.as_mut_ptr(),
            )
        };
        Some(out)
    }

    /// Cast a ray from `pnt` along `vec` (`mj_ray`). `geomgroup` (6 flags) selects
    /// geom groups, `include_static` includes geoms of the world body, and
    /// `body_exclude` skips one body. Returns `(distance in units of |vec|, geom id)`.
    pub fn ray(
        &self,
        pnt: [f64; 3],
        vec: [f64; 3],
        geomgroup: Option<&[u8; 6]>,
        include_static: bool,
        body_exclude: Option<usize>,
    ) -> Option<(f64, usize)> {
        let mut geomid: i32 = -1;
        let group = geomgroup.map_or(std::ptr::null(), |g| g.as_ptr());
        let exclude = body_exclude.map_or(-1, |b| b as i32);
        // SAFETY: valid model/data after kinematics; pnt/vec are 3 doubles;
        // geomgroup is NULL or 6 bytes (mjNGROUP); geomid is one int.
        let dist = unsafe {
            sys::mj_ray(
                self.model.as_ptr(),
                self.ptr.as_ptr(),
                pnt.as_ptr(),
                vec.as_ptr(),
                group,
                include_static as u8,
                exclude,
                &mut geomid,
            )
        };
        (dist >= 0.0 && geomid >= 0).then_some((dist, geomid as usize))
    }
}
