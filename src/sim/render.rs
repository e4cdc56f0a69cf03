//! Headless offscreen rendering through MuJoCo's own renderer (`mjr_*`,
//! `mjv_*`) in an OSMesa context: no display, no GPU, Debian's `libosmesa6`
//! (Mesa's software rasterizer), loaded at run time so that nothing else in the
//! crate needs it.
//!
//! MuJoCo does not create OpenGL contexts; it renders into whatever context is
//! current and finds the GL functions through the context library's
//! `*GetProcAddress`, which both 2.2.2 and 3.x look up among the process's
//! global symbols (`OSMesaGetProcAddress` among them). So the library is
//! opened with `RTLD_GLOBAL`, a context is made current on this thread, and
//! `mjr_makeContext` then draws into its own offscreen framebuffer, sized by
//! the model's `visual.global.offwidth/offheight` (set here on the renderer's
//! private copy of the model).
//!
//! The renderer keeps its own `mjData`: [`Renderer::render`] copies the state
//! of the `Data` it is given (qpos, qvel, act, mocap, time) and runs
//! `mj_forward` on it, so a rollout's own `Data` is only read.
use std::ffi::{c_char, c_int, c_uint, c_void, CStr, CString};
use std::sync::Arc;

use mujoco_sys as sys;

use super::{Data, Model, SimError};

/// The OSMesa library `render` opens (Debian 12: package `libosmesa6`).
pub const OSMESA_LIBRARY: &str = "libOSMesa.so.8";
const GL_RGBA: c_uint = 0x1908;
const GL_UNSIGNED_BYTE: c_uint = 0x1401;
const GL_VERSION: c_uint = 0x1F02;
const GL_RENDERER: c_uint = 0x1F01;
/// Most geoms a scene holds (the G1 has ~60, a heightfield is one).
const MAX_GEOM: c_int = 2000;
/// Largest frame side accepted (pixels): MuJoCo's offscreen buffer is one
/// allocation of width x height x (RGB + depth).
pub const MAX_SIDE: usize = 4096;

type CreateContextExt =
    unsafe extern "C" fn(c_uint, c_int, c_int, c_int, *mut c_void) -> *mut c_void;
type MakeCurrent = unsafe extern "C" fn(*mut c_void, *mut c_void, c_uint, c_int, c_int) -> u8;
type DestroyContext = unsafe extern "C" fn(*mut c_void);
type GetProcAddress = unsafe extern "C" fn(*const c_char) -> *mut c_void;
type GetString = unsafe extern "C" fn(c_uint) -> *const u8;

/// An OSMesa context current on the thread that made it, drawing into a
/// buffer it owns.
struct OsMesa {
    ctx: *mut c_void,
    destroy: DestroyContext,
    /// The context's default framebuffer (MuJoCo draws into its own FBO).
    _buffer: Vec<u8>,
    /// `GL_VERSION` and `GL_RENDERER` of the context.
    version: String,
}

fn dl_error() -> String {
    // SAFETY: dlerror returns NULL or a NUL-terminated string valid until the next dl* call.
    let p = unsafe { libc::dlerror() };
    if p.is_null() {
        "unknown error".into()
    } else {
        // SAFETY: see above.
        unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
    }
}

/// `name` from `lib`, as a function pointer of type `F`.
///
/// # Safety
/// `F` must be the C signature of `name`.
unsafe fn symbol<F: Copy>(lib: *mut c_void, name: &str) -> Result<F, SimError> {
    let c = CString::new(name).expect("symbol names have no NUL");
    // SAFETY: lib is a live dlopen handle and c a NUL-terminated name.
    let p = unsafe { libc::dlsym(lib, c.as_ptr()) };
    if p.is_null() {
        return Err(SimError::Render(format!(
            "{OSMESA_LIBRARY} has no {name}: {}",
            dl_error()
        )));
    }
    debug_assert_eq!(std::mem::size_of::<F>(), std::mem::size_of::<*mut c_void>());
    // SAFETY: p is the address of a function whose signature the caller vouches for.
    Ok(unsafe { std::mem::transmute_copy::<*mut c_void, F>(&p) })
}

impl OsMesa {
    fn new(width: usize, height: usize) -> Result<OsMesa, SimError> {
        let name = CString::new(OSMESA_LIBRARY).expect("no NUL");
        // SAFETY: dlopen with a NUL-terminated name; RTLD_GLOBAL puts
        // OSMesaGetProcAddress where MuJoCo's GL loader looks for it.
        let lib = unsafe { libc::dlopen(name.as_ptr(), libc::RTLD_NOW | libc::RTLD_GLOBAL) };
        if lib.is_null() {
            return Err(SimError::Render(format!(
                "cannot load {OSMESA_LIBRARY} ({}): install Debian's libosmesa6 \
                 (scripts/setup.sh does) to render headless",
                dl_error()
            )));
        }
        // SAFETY: the signatures are OSMesa's (GL/osmesa.h).
        let (create, make_current, destroy, get_proc) = unsafe {
            (
                symbol::<CreateContextExt>(lib, "OSMesaCreateContextExt")?,
                symbol::<MakeCurrent>(lib, "OSMesaMakeCurrent")?,
                symbol::<DestroyContext>(lib, "OSMesaDestroyContext")?,
                symbol::<GetProcAddress>(lib, "OSMesaGetProcAddress")?,
            )
        };
        // SAFETY: RGBA, 24 depth bits, 8 stencil bits, no accumulation, no sharing.
        let ctx = unsafe { create(GL_RGBA, 24, 8, 0, std::ptr::null_mut()) };
        if ctx.is_null() {
            return Err(SimError::Render(
                "OSMesaCreateContextExt failed to create a context".into(),
            ));
        }
        let mut buffer = vec![0u8; width * height * 4];
        // SAFETY: ctx is live; buffer holds width x height RGBA bytes and lives
        // as long as the context (it is a field of the returned struct).
        let ok = unsafe {
            make_current(
                ctx,
                buffer.as_mut_ptr().cast(),
                GL_UNSIGNED_BYTE,
                width as c_int,
                height as c_int,
            )
        };
        let mut me = OsMesa {
            ctx,
            destroy,
            _buffer: buffer,
            version: String::new(),
        };
        if ok == 0 {
            return Err(SimError::Render(
                "OSMesaMakeCurrent failed: no OpenGL context to render in".into(),
            ));
        }
        let gs = CString::new("glGetString").expect("no NUL");
        // SAFETY: a current context exists; the returned pointer is glGetString's.
        let p = unsafe { get_proc(gs.as_ptr()) };
        if !p.is_null() {
            // SAFETY: glGetString's signature.
            let get_string: GetString = unsafe { std::mem::transmute_copy(&p) };
            let text = |what| {
                // SAFETY: a current context; GL returns NULL or a static string.
                let s = unsafe { get_string(what) };
                if s.is_null() {
                    String::new()
                } else {
                    // SAFETY: non-null NUL-terminated static string.
                    unsafe { CStr::from_ptr(s.cast()) }
                        .to_string_lossy()
                        .into_owned()
                }
            };
            me.version = format!("{} ({})", text(GL_VERSION), text(GL_RENDERER));
        }
        if me.version.is_empty() || me.version.starts_with(" (") {
            return Err(SimError::Render(
                "the OSMesa context reports no OpenGL version".into(),
            ));
        }
        Ok(me)
    }
}

impl Drop for OsMesa {
    fn drop(&mut self) {
        // SAFETY: the context was created by this struct and is destroyed once.
        // The library stays loaded: MuJoCo keeps the GL function pointers.
        unsafe { (self.destroy)(self.ctx) };
    }
}

/// Where the camera looks from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraView {
    /// Body the camera follows (MuJoCo's tracking camera: it looks at the
    /// body's subtree centre of mass).
    pub track_body: usize,
    /// Distance from the tracked point (m).
    pub distance: f64,
    /// Degrees about +z; 90 looks along +y, i.e. at a robot walking along +x
    /// from its right side.
    pub azimuth: f64,
    /// Degrees above the horizon (negative: looking down).
    pub elevation: f64,
}

impl CameraView {
    /// A three-quarter view from the robot's right front, 3 m away, 15 degrees
    /// from above, following `track_body`.
    pub fn follow(track_body: usize) -> CameraView {
        CameraView {
            track_body,
            distance: 3.0,
            azimuth: 120.0,
            elevation: -15.0,
        }
    }
}

/// MuJoCo's offscreen renderer on a private copy of a model: RGB frames of a
/// fixed size, top row first. Not `Send`: its GL context is current on the
/// thread that made it.
pub struct Renderer {
    width: usize,
    height: usize,
    // drop order: the MuJoCo objects before the model and the GL context
    scene: Box<sys::mjvScene>,
    context: Box<sys::mjrContext>,
    option: Box<sys::mjvOption>,
    camera: sys::mjvCamera,
    data: Data,
    model: Arc<Model>,
    gl: OsMesa,
    rows: Vec<u8>,
    frame: Vec<u8>,
}

impl Renderer {
    /// A renderer of `width` x `height` frames for `model` (copied: the copy's
    /// offscreen buffer is resized to the frame).
    pub fn new(model: &Model, width: usize, height: usize) -> Result<Renderer, SimError> {
        if !(16..=MAX_SIDE).contains(&width) || !(16..=MAX_SIDE).contains(&height) {
            return Err(SimError::Render(format!(
                "frame size must be 16..={MAX_SIDE} pixels a side, got {width}x{height}"
            )));
        }
        let gl = OsMesa::new(width, height)?;
        let mut model = model.clone();
        {
            let vis = &mut model.raw_mut().vis.global;
            vis.offwidth = width as c_int;
            vis.offheight = height as c_int;
        }
        let model = Arc::new(model);
        let data = Data::new(model.clone())?;
        // SAFETY: these structs are plain C data that the mjv/mjr default
        // functions initialise in full before any other use.
        let (mut scene, mut context, mut option, mut camera) = unsafe {
            (
                Box::new(std::mem::zeroed::<sys::mjvScene>()),
                Box::new(std::mem::zeroed::<sys::mjrContext>()),
                Box::new(std::mem::zeroed::<sys::mjvOption>()),
                std::mem::zeroed::<sys::mjvCamera>(),
            )
        };
        let m = model.as_ptr();
        // SAFETY: valid model; the structs are owned here and freed in Drop; a
        // GL context is current on this thread (gl).
        unsafe {
            sys::mjv_defaultScene(&mut *scene);
            sys::mjv_defaultOption(&mut *option);
            sys::mjv_defaultCamera(&mut camera);
            sys::mjr_defaultContext(&mut *context);
            sys::mjv_makeScene(m, &mut *scene, MAX_GEOM);
            sys::mjr_makeContext(m, &mut *context, sys::mjFONTSCALE_150 as c_int);
            sys::mjr_setBuffer(sys::mjFB_OFFSCREEN as c_int, &mut *context);
        }
        let mut r = Renderer {
            width,
            height,
            scene,
            context,
            option,
            camera,
            data,
            model,
            gl,
            rows: vec![0; width * height * 3],
            frame: vec![0; width * height * 3],
        };
        if r.context.currentBuffer != sys::mjFB_OFFSCREEN as c_int {
            return Err(SimError::Render(
                "MuJoCo could not bind its offscreen framebuffer in the OSMesa context".into(),
            ));
        }
        if (r.context.offWidth as usize) < width || (r.context.offHeight as usize) < height {
            return Err(SimError::Render(format!(
                "MuJoCo's offscreen buffer is {}x{}, smaller than the {width}x{height} frame",
                r.context.offWidth, r.context.offHeight
            )));
        }
        r.set_view(CameraView::follow(root_body(&r.model)));
        r.set_shadows(false);
        Ok(r)
    }

    /// The OpenGL version and renderer of the context, e.g.
    /// "4.5 (Compatibility Profile) Mesa 22.3.6 (llvmpipe ...)".
    pub fn gl_version(&self) -> &str {
        &self.gl.version
    }

    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Point the camera: track a body from a distance, azimuth and elevation.
    pub fn set_view(&mut self, v: CameraView) {
        let c = &mut self.camera;
        c.type_ = sys::mjCAMERA_TRACKING as c_int;
        c.trackbodyid = v.track_body as c_int;
        c.fixedcamid = -1;
        c.distance = v.distance;
        c.azimuth = v.azimuth;
        c.elevation = v.elevation;
    }

    /// Draw shadows (off by default: they cost 2-3x the frame time in the
    /// software rasterizer, and the plane's shows acne at low angles).
    pub fn set_shadows(&mut self, on: bool) {
        self.scene.flags[sys::mjRND_SHADOW as usize] = on as u8;
    }

    /// Render the state of `src` (a `Data` of a model with the same sizes);
    /// the RGB frame, `width x height x 3` bytes, top row first.
    pub fn render(&mut self, src: &Data) -> Result<&[u8], SimError> {
        let (a, b) = (self.model.raw(), src.model().raw());
        if (a.nq, a.nv, a.na, a.nmocap, a.ngeom) != (b.nq, b.nv, b.na, b.nmocap, b.ngeom) {
            return Err(SimError::Render(format!(
                "the state to render is of another model ({} vs {})",
                src.model().source(),
                self.model.source()
            )));
        }
        {
            let (s, d) = (src.raw(), self.data.raw_mut());
            d.time = s.time;
            let nmocap = a.nmocap as usize;
            // SAFETY: both datas belong to models of equal sizes (checked above),
            // so each array holds the same number of elements on both sides.
            unsafe {
                std::ptr::copy_nonoverlapping(s.qpos, d.qpos, a.nq as usize);
                std::ptr::copy_nonoverlapping(s.qvel, d.qvel, a.nv as usize);
                std::ptr::copy_nonoverlapping(s.act, d.act, a.na as usize);
                std::ptr::copy_nonoverlapping(s.mocap_pos, d.mocap_pos, 3 * nmocap);
                std::ptr::copy_nonoverlapping(s.mocap_quat, d.mocap_quat, 4 * nmocap);
            }
        }
        self.data.forward();
        // MuJoCo 2.2.2 eases a tracking camera's look-at point toward the body
        // over several frames (3.x puts it there at once): starting each frame
        // on the body gives the same picture in both and no glide at the start
        let track = self.camera.trackbodyid as usize;
        if let Some(com) = self.data.subtree_com().get(track) {
            self.camera.lookat = *com;
        }
        let viewport = sys::mjrRect {
            left: 0,
            bottom: 0,
            width: self.width as c_int,
            height: self.height as c_int,
        };
        let (m, d) = self.data.as_raw_ptrs();
        // SAFETY: model, data, scene and context are live and belong together;
        // the GL context is current on this thread (Renderer is not Send); rows
        // holds width x height RGB bytes.
        unsafe {
            sys::mjv_updateScene(
                m,
                d,
                &*self.option,
                std::ptr::null(),
                &mut self.camera,
                sys::mjCAT_ALL as c_int,
                &mut *self.scene,
            );
            sys::mjr_render(viewport, &mut *self.scene, &*self.context);
            sys::mjr_readPixels(
                self.rows.as_mut_ptr(),
                std::ptr::null_mut(),
                viewport,
                &*self.context,
            );
        }
        // OpenGL's rows run bottom to top
        let stride = self.width * 3;
        for (y, row) in self.rows.chunks_exact(stride).enumerate() {
            let to = (self.height - 1 - y) * stride;
            self.frame[to..to + stride].copy_from_slice(row);
        }
        Ok(&self.frame)
    }
}

impl Drop for Renderer {
    fn drop(&mut self) {
        // SAFETY: made in `new`, freed once, with the GL context still current
        // (gl drops after this body).
        unsafe {
            sys::mjr_freeContext(&mut *self.context);
            sys::mjv_freeScene(&mut *self.scene);
        }
    }
}

/// The body of the model's first free joint (the robot's pelvis), or body 1.
pub fn root_body(model: &Model) -> usize {
    let m = model.raw();
    // SAFETY: jnt_type and jnt_bodyid hold njnt entries.
    let (types, bodies) = unsafe {
        (
            super::model::slice(m.jnt_type, m.njnt as usize),
            super::model::slice(m.jnt_bodyid, m.njnt as usize),
        )
    };
    types
        .iter()
        .zip(bodies)
        .find(|(t, _)| **t == sys::mjJNT_FREE as c_int)
        .map_or(1.min(m.nbody as usize - 1), |(_, b)| *b as usize)
}
