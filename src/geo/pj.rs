//! A thin, safe wrapper over the parts of the PROJ C API (through `proj-sys`) that the CRS layer needs:
//! database look-ups, CRS introspection (type, sub-CRSs, axes, units), `proj_create_crs_to_crs` and
//! batch transformation.
//!
//! Why not the `proj` crate: it offers neither CRS introspection (compound sub-CRSs, axis order) nor 3D
//! batch calls, and its `Drop` calls `proj_cleanup()`, which tears down PROJ's process-wide state while
//! other threads may still hold live contexts. Here every [`Context`] is independent, PROJ's log output
//! is captured into the context (so error messages can quote it) instead of going to stderr, network
//! access is off, and `proj_cleanup` is never called.
//!
//! Safety model: a [`Context`] owns one `PJ_CONTEXT`; an [`Obj`] owns one `PJ` created with some
//! context and must be dropped before that context. Owners in this crate guarantee that by field order
//! (objects declared before the context) or by scoping. Neither type is `Sync`; both may be moved to
//! another thread together (PROJ allows a context and its objects to migrate, just not to be shared).

use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::ptr;
use std::sync::Mutex;

use proj_sys as sys;

use super::error::CsPart;
use super::ProjError;

/// PROJ's "transformation failed" marker value (`HUGE_VAL`).
const HUGE: f64 = f64::INFINITY;

/// Converts a possibly-null C string owned by PROJ into an owned Rust string.
///
/// # Safety
/// `s` must be null or point at a NUL-terminated string valid for the duration of the call.
unsafe fn c_str(s: *const c_char) -> Option<String> {
    if s.is_null() {
        None
    } else {
        Some(CStr::from_ptr(s).to_string_lossy().into_owned())
    }
}

/// PROJ's log callback: keeps the most recent error message of the context.
unsafe extern "C" fn capture_log(app_data: *mut c_void, _level: c_int, msg: *const c_char) {
    if app_data.is_null() || msg.is_null() {
        return;
    }
    // SAFETY: app_data is the `Mutex<String>` boxed in `Context::new`, alive as long as the context.
    let buf = &*(app_data as *const Mutex<String>);
    if let Ok(mut b) = buf.lock() {
        b.clear();
        b.push_str(&CStr::from_ptr(msg).to_string_lossy());
    }
}

/// One PROJ context (database connection, grid cache, error state, captured log).
pub(crate) struct Context {
    ptr: *mut sys::PJ_CONTEXT,
    /// Last PROJ log message; boxed so its address stays fixed for the C callback.
    log: Box<Mutex<String>>,
}

// SAFETY: the context is exclusively owned and never shared; PROJ permits moving a context (and the
// objects created with it, which always travel together with it in this crate) to another thread.
unsafe impl Send for Context {}

impl Context {
    /// Creates a context with network access disabled and PROJ's log captured.
    pub(crate) fn new() -> Result<Context, ProjError> {
        // SAFETY: plain constructor; null is checked.
        let ptr = unsafe { sys::proj_context_create() };
        if ptr.is_null() {
            return Err(ProjError::NoContext);
        }
        let log = Box::new(Mutex::new(String::new()));
        // SAFETY: ptr is a live context; the log box outlives it (dropped after proj_context_destroy).
        unsafe {
            sys::proj_context_set_enable_network(ptr, 0);
            sys::proj_log_level(ptr, sys::PJ_LOG_LEVEL_PJ_LOG_ERROR);
            sys::proj_log_func(ptr, &*log as *const Mutex<String> as *mut c_void, Some(capture_log));
        }
        Ok(Context { ptr, log })
    }

    /// The context's last error: PROJ's logged message if any, else the text of its error number.
    pub(crate) fn last_error(&self) -> String {
        let logged = self.log.lock().map(|mut b| std::mem::take(&mut *b)).unwrap_or_default();
        // SAFETY: live context; the returned string is static or owned by the context.
        let errno_text = unsafe {
            let e = sys::proj_context_errno(self.ptr);
            if e == 0 {
                None
            } else {
                c_str(sys::proj_context_errno_string(self.ptr, e))
            }
        };
        match (logged.is_empty(), errno_text) {
            (false, _) => logged,
            (true, Some(t)) => t,
            (true, None) => "PROJ reported no reason".into(),
        }
    }

    fn clear_error(&self) {
        if let Ok(mut b) = self.log.lock() {
            b.clear();
        }
        // (PROJ has no public call to reset a context's errno; the captured log is the primary source.)
    }

    /// The object `ptr`, or, when PROJ returned null, the error `fail` builds from PROJ's reason.
    fn wrap(&self, ptr: *mut sys::PJ, fail: impl FnOnce(String) -> ProjError) -> Result<Obj, ProjError> {
        if ptr.is_null() {
            Err(fail(self.last_error()))
        } else {
            Ok(Obj { ptr })
        }
    }

    /// Looks up a CRS in PROJ's database (`proj.db`) by authority and code.
    pub(crate) fn crs_from_database(&self, auth: &str, code: u32) -> Result<Obj, ProjError> {
        self.clear_error();
        let auth_c = CString::new(auth)
            .map_err(|_| ProjError::Nul { what: "authority name", value: auth.to_string() })?;
        let code_c = CString::new(code.to_string()).expect("decimal digits contain no NUL");
        // SAFETY: live context, valid C strings, null options.
        let ptr = unsafe {
            sys::proj_create_from_database(
                self.ptr,
                auth_c.as_ptr(),
                code_c.as_ptr(),
                sys::PJ_CATEGORY_PJ_CATEGORY_CRS,
                0,
                ptr::null(),
            )
        };
        self.wrap(ptr, |reason| ProjError::NotInDatabase {
            auth: auth.to_string(),
            code,
            database: self.database_path(),
            reason,
        })
    }

    /// The path of the `proj.db` this context uses.
    pub(crate) fn database_path(&self) -> String {
        // SAFETY: live context; the string is owned by the context.
        unsafe { c_str(sys::proj_context_get_database_path(self.ptr)) }.unwrap_or_else(|| "proj.db".into())
    }

    /// The i-th component of a compound CRS.
    pub(crate) fn sub_crs(&self, crs: &Obj, index: i32) -> Result<Obj, ProjError> {
        self.clear_error();
        // SAFETY: live context and object.
        let ptr = unsafe { sys::proj_crs_get_sub_crs(self.ptr, crs.ptr, index) };
        self.wrap(ptr, |reason| ProjError::SubCrs { crs: crs.name(), index, reason })
    }

    /// The axes of a CRS's coordinate system, in the CRS's (authority) order.
    pub(crate) fn axes(&self, crs: &Obj) -> Result<Vec<AxisInfo>, ProjError> {
        self.clear_error();
        let fail = |part: CsPart, reason: String| ProjError::Axes { part, crs: crs.name(), reason };
        // SAFETY: live context and object.
        let cs = self.wrap(unsafe { sys::proj_crs_get_coordinate_system(self.ptr, crs.ptr) }, |reason| {
            fail(CsPart::CoordinateSystem, reason)
        })?;
        // SAFETY: live context and object.
        let n = unsafe { sys::proj_cs_get_axis_count(self.ptr, cs.ptr) };
        if n < 0 {
            return Err(fail(CsPart::AxisCount, self.last_error()));
        }
        let mut out = Vec::with_capacity(n as usize);
        for i in 0..n {
            let mut name: *const c_char = ptr::null();
            let mut abbrev: *const c_char = ptr::null();
            let mut direction: *const c_char = ptr::null();
            let mut factor = 0.0f64;
            let mut unit: *const c_char = ptr::null();
            // SAFETY: live context and object; all out-pointers point at locals; strings returned are
            // owned by `cs`, which lives until the end of this function, and are copied right away.
            let ok = unsafe {
                sys::proj_cs_get_axis_info(
                    self.ptr,
                    cs.ptr,
                    i,
                    &mut name,
                    &mut abbrev,
                    &mut direction,
                    &mut factor,
                    &mut unit,
                    ptr::null_mut(),
                    ptr::null_mut(),
                )
            };
            if ok == 0 {
                return Err(fail(CsPart::Axis(i), self.last_error()));
            }
            // SAFETY: strings from PROJ as described above.
            unsafe {
                out.push(AxisInfo {
                    name: c_str(name).unwrap_or_default(),
                    abbrev: c_str(abbrev).unwrap_or_default(),
                    direction: c_str(direction).unwrap_or_default(),
                    unit_factor: factor,
                    unit: c_str(unit).unwrap_or_default(),
                });
            }
        }
        Ok(out)
    }

    /// The area of use `[west, south, east, north]` in degrees (west > east across the antimeridian).
    pub(crate) fn area_of_use(&self, obj: &Obj) -> Option<[f64; 4]> {
        let (mut w, mut s, mut e, mut n) = (0.0, 0.0, 0.0, 0.0);
        // SAFETY: live context and object; out-pointers to locals; the name is not requested.
        let ok = unsafe {
            sys::proj_get_area_of_use(self.ptr, obj.ptr, &mut w, &mut s, &mut e, &mut n, ptr::null_mut())
        };
        (ok != 0 && w > -1000.0).then_some([w, s, e, n])
    }

    /// PROJ's `proj_create_crs_to_crs` between two CRS objects: all candidate operations, the one to
    /// use chosen per point by area of use (exactly as pyproj's `Transformer.from_crs`). Input and
    /// output in the CRSs' authority axis order.
    pub(crate) fn crs_to_crs(&self, src: &Obj, dst: &Obj) -> Result<Obj, ProjError> {
        self.clear_error();
        // SAFETY: live context and objects; null area and options.
        let ptr = unsafe {
            sys::proj_create_crs_to_crs_from_pj(self.ptr, src.ptr, dst.ptr, ptr::null_mut(), ptr::null())
        };
        self.wrap(ptr, |reason| ProjError::NoOperation { from: src.name(), to: dst.name(), reason })
    }

    /// The same operation with input and output in "visualisation" order: longitude/easting first.
    pub(crate) fn normalize_for_visualization(&self, op: &Obj) -> Result<Obj, ProjError> {
        self.clear_error();
        // SAFETY: live context and object.
        let ptr = unsafe { sys::proj_normalize_for_visualization(self.ptr, op.ptr) };
        self.wrap(ptr, |reason| ProjError::Normalize { operation: op.name(), reason })
    }

    /// Creates an object from a PROJ string, a user CRS string (`EPSG:6668+6695`) or a WKT/PROJJSON
    /// definition.
    pub(crate) fn create(&self, definition: &str) -> Result<Obj, ProjError> {
        self.clear_error();
        let def = CString::new(definition)
            .map_err(|_| ProjError::Nul { what: "definition", value: definition.to_string() })?;
        // SAFETY: live context, valid C string.
        let ptr = unsafe { sys::proj_create(self.ptr, def.as_ptr()) };
        self.wrap(ptr, |reason| ProjError::Create { definition: definition.to_string(), reason })
    }

    /// Transforms coordinates in place through `op` (forward or inverse). `z` may be empty (2D).
    /// Returns, for the first point PROJ could not transform, its index and PROJ's reason.
    pub(crate) fn trans(
        &self,
        op: &Obj,
        inverse: bool,
        x: &mut [f64],
        y: &mut [f64],
        z: &mut [f64],
    ) -> Result<(), (usize, String)> {
        debug_assert!(x.len() == y.len() && (z.is_empty() || z.len() == x.len()));
        let n = x.len();
        if n == 0 {
            return Ok(());
        }
        let dir = if inverse { sys::PJ_DIRECTION_PJ_INV } else { sys::PJ_DIRECTION_PJ_FWD };
        let st = std::mem::size_of::<f64>();
        let (zp, nz) = if z.is_empty() { (ptr::null_mut(), 0) } else { (z.as_mut_ptr(), n) };
        self.clear_error();
        // SAFETY: live op; x, y (and z if given) are distinct, contiguous slices of n f64 each; t is
        // omitted (null, count 0).
        unsafe {
            sys::proj_errno_reset(op.ptr);
            sys::proj_trans_generic(
                op.ptr,
                dir,
                x.as_mut_ptr(),
                st,
                n,
                y.as_mut_ptr(),
                st,
                n,
                zp,
                st,
                nz,
                ptr::null_mut(),
                0,
                0,
            );
        }
        let bad = (0..n).find(|&i| {
            !(x[i].is_finite() && y[i].is_finite() && x[i] != HUGE && (z.is_empty() || z[i].is_finite()))
        });
        match bad {
            None => Ok(()),
            Some(i) => {
                // SAFETY: live op.
                let e = unsafe { sys::proj_errno(op.ptr) };
                let mut why = self.last_error();
                if e != 0 && why == "PROJ reported no reason" {
                    // SAFETY: static or context-owned string.
                    why = unsafe { c_str(sys::proj_context_errno_string(self.ptr, e)) }.unwrap_or(why);
                }
                Err((i, why))
            }
        }
    }

    /// The operation `op` used for its most recent transformed point (for an operation with several
    /// candidates, the one PROJ picked); `None` when PROJ keeps none (a single operation).
    pub(crate) fn last_used_operation_obj(&self, op: &Obj) -> Option<Obj> {
        // SAFETY: live op; the result is a new object (or null) that we own.
        let used = unsafe { sys::proj_trans_get_last_used_operation(op.ptr) };
        (!used.is_null()).then_some(Obj { ptr: used })
    }

    /// The grids a coordinate operation (single or concatenated) needs, with whether PROJ found them.
    pub(crate) fn grids_used(&self, op: &Obj) -> Vec<GridUsed> {
        // SAFETY: live context and object.
        let n = unsafe { sys::proj_coordoperation_get_grid_used_count(self.ptr, op.ptr) };
        let mut out = Vec::new();
        for i in 0..n.max(0) {
            let (mut short, mut full, mut package, mut url) =
                (ptr::null(), ptr::null(), ptr::null(), ptr::null());
            let (mut direct, mut open, mut available) = (0, 0, 0);
            // SAFETY: live context and object, index in range; out-pointers to locals; the strings are
            // owned by the operation and copied right away.
            let ok = unsafe {
                sys::proj_coordoperation_get_grid_used(
                    self.ptr,
                    op.ptr,
                    i,
                    &mut short,
                    &mut full,
                    &mut package,
                    &mut url,
                    &mut direct,
                    &mut open,
                    &mut available,
                )
            };
            if ok == 0 {
                continue;
            }
            // SAFETY: strings from PROJ as described above.
            unsafe {
                out.push(GridUsed {
                    short_name: c_str(short).unwrap_or_default(),
                    full_name: c_str(full).unwrap_or_default(),
                    available: available != 0,
                });
            }
        }
        out
    }

    /// Every candidate operation from `src` to `dst` whose area of use meets the CRSs', best first, as
    /// PROJ ranks them with grid availability *ignored* — so operations whose grids are not installed
    /// are listed too (that is how to learn which grid PROJ would have wanted).
    pub(crate) fn operations_ignoring_grids(&self, src: &Obj, dst: &Obj) -> Vec<Obj> {
        // SAFETY: live context; the factory context and list are destroyed below; each listed object
        // taken with proj_list_get is a new object that we own.
        unsafe {
            let factory = sys::proj_create_operation_factory_context(self.ptr, ptr::null());
            if factory.is_null() {
                return Vec::new();
            }
            sys::proj_operation_factory_context_set_grid_availability_use(
                self.ptr,
                factory,
                sys::PROJ_GRID_AVAILABILITY_USE_PROJ_GRID_AVAILABILITY_IGNORED,
            );
            sys::proj_operation_factory_context_set_spatial_criterion(
                self.ptr,
                factory,
                sys::PROJ_SPATIAL_CRITERION_PROJ_SPATIAL_CRITERION_PARTIAL_INTERSECTION,
            );
            let list = sys::proj_create_operations(self.ptr, src.ptr, dst.ptr, factory);
            let mut out = Vec::new();
            if !list.is_null() {
                for i in 0..sys::proj_list_get_count(list) {
                    let o = sys::proj_list_get(self.ptr, list, i);
                    if !o.is_null() {
                        out.push(Obj { ptr: o });
                    }
                }
                sys::proj_list_destroy(list);
            }
            sys::proj_operation_factory_context_destroy(factory);
            out
        }
    }

    /// Whether PROJ can run the operation here (all its grids are installed).
    pub(crate) fn is_instantiable(&self, op: &Obj) -> bool {
        // SAFETY: live context and object.
        unsafe { sys::proj_coordoperation_is_instantiable(self.ptr, op.ptr) != 0 }
    }

    /// The description of the operation `op` used for its most recent transformed point (for an
    /// operation with several candidates, the one PROJ picked).
    pub(crate) fn last_used_operation(&self, op: &Obj) -> String {
        // SAFETY: live op; the result is a new object (or null) that we own.
        let used = unsafe { sys::proj_trans_get_last_used_operation(op.ptr) };
        if used.is_null() {
            return op.description();
        }
        let used = Obj { ptr: used };
        used.description()
    }
}

impl Drop for Context {
    fn drop(&mut self) {
        // SAFETY: every Obj created with this context has been dropped before (see module doc).
        unsafe {
            sys::proj_context_destroy(self.ptr);
        }
    }
}

/// One axis of a coordinate system, as PROJ describes it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct AxisInfo {
    pub name: String,
    pub abbrev: String,
    /// "north", "east", "up", "geocentricX", …
    pub direction: String,
    /// Metres (or radians) per unit of this axis.
    pub unit_factor: f64,
    pub unit: String,
}

/// A grid a coordinate operation needs (`proj_coordoperation_get_grid_used`).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct GridUsed {
    /// The name PROJ's database gives (`jp_gsi_gsigeo2011.tif`).
    pub short_name: String,
    /// The file PROJ found in its search path (empty when not installed).
    pub full_name: String,
    /// Whether the grid is installed where PROJ looks.
    pub available: bool,
}

/// One PROJ object (CRS or coordinate operation). Must be dropped before its [`Context`].
pub(crate) struct Obj {
    ptr: *mut sys::PJ,
}

// SAFETY: see `Context`: an Obj only ever moves together with its owning context.
unsafe impl Send for Obj {}

impl Obj {
    /// PROJ's type of the object (`PJ_TYPE_*`).
    pub(crate) fn kind(&self) -> sys::PJ_TYPE {
        // SAFETY: live object.
        unsafe { sys::proj_get_type(self.ptr) }
    }

    /// The object's name ("JGD2011 + JGD2011 (vertical) height").
    pub(crate) fn name(&self) -> String {
        // SAFETY: live object; the string is owned by it and copied.
        unsafe { c_str(sys::proj_get_name(self.ptr)) }.unwrap_or_else(|| "(unnamed)".into())
    }

    /// The object's first identifier as (authority, code), e.g. ("EPSG", "6668").
    pub(crate) fn id(&self) -> Option<(String, String)> {
        // SAFETY: live object; strings owned by it and copied.
        unsafe {
            let auth = c_str(sys::proj_get_id_auth_name(self.ptr, 0))?;
            let code = c_str(sys::proj_get_id_code(self.ptr, 0))?;
            Some((auth, code))
        }
    }

    /// For an operation: PROJ's human-readable description.
    pub(crate) fn description(&self) -> String {
        // SAFETY: live object; strings owned by it and copied.
        let info = unsafe { sys::proj_pj_info(self.ptr) };
        unsafe { c_str(info.description) }.unwrap_or_else(|| self.name())
    }
}

impl Drop for Obj {
    fn drop(&mut self) {
        // SAFETY: live object, destroyed once; its context is still alive (see module doc).
        unsafe {
            sys::proj_destroy(self.ptr);
        }
    }
}

/// The version of the linked PROJ library, e.g. "9.1.1".
pub(crate) fn proj_version() -> String {
    // SAFETY: proj_info returns static strings.
    let info = unsafe { sys::proj_info() };
    unsafe { c_str(info.version) }.unwrap_or_default()
}

/// PROJ's resource search path (where `proj.db` and grids are looked up), as directories.
pub(crate) fn proj_search_paths() -> Vec<String> {
    // SAFETY: proj_info returns static strings.
    let info = unsafe { sys::proj_info() };
    let s = unsafe { c_str(info.searchpath) }.unwrap_or_default();
    let sep = if cfg!(windows) { ';' } else { ':' };
    s.split(sep).filter(|p| !p.is_empty()).map(str::to_string).collect()
}
