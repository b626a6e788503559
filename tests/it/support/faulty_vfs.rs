//! A SQLite VFS that fails the writes to a database's WAL on command: the I/O error at
//! commit of issue 53 (tests/it/store/io_error.rs).
//!
//! Decisions:
//! - **Why a VFS.** sqlx offers no hook into SQLite's I/O, and a real `EIO` from the
//!   kernel needs a failing block device (device-mapper's `error` or `flakey` target),
//!   which a container cannot set up. SQLite does all its file I/O through a VFS, and a
//!   program may register one of its own beside the built-in ones; rackd opens its file
//!   through the one `database.sqlite_vfs` names. So the fault is SQLite's own answer to a
//!   failed `write(2)`, at the very call that failed, and rackd needs no seam of its own.
//! - **What fails.** Only `xWrite` on a WAL file (opened with `SQLITE_OPEN_WAL`) of a
//!   database a test has [`watch`]ed, and only while its [`Switch`] is armed: it answers
//!   `SQLITE_IOERR_WRITE` without writing. A commit in WAL mode writes its pages there (a
//!   large transaction may spill some before its `COMMIT`), so every commit fails while
//!   armed, and SQLite rolls the transaction back; the database file, the `-shm` index and
//!   every read are untouched, and the sync of the WAL (rackd's own `fdatasync`, on a file
//!   handle of rackd's, not SQLite's) is not faulted.
//! - **Everything else is forwarded.** The VFS is a copy of SQLite's default (`unix`)
//!   with its own `xOpen`, which opens the real file in the space just after its own
//!   header and hands SQLite methods that call the real file's. The copied methods
//!   (`xDelete`, `xAccess`, `xFullPathname`, ...) do not use the VFS pointer they are
//!   given, which is what makes a copy enough (`os_unix.c`: their `pVfs` is `NotUsed`).
//! - **Unsafe, and only here.** This is FFI with SQLite's C structs, so `unsafe`; the
//!   crate denies it everywhere else, and the library and the binary forbid it.

#![allow(unsafe_code)]

use std::ffi::{CStr, c_char, c_int, c_void};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicPtr, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use libsqlite3_sys::{
    SQLITE_IOERR_WRITE, SQLITE_OK, SQLITE_OPEN_WAL, sqlite3_file, sqlite3_int64, sqlite3_io_methods,
    sqlite3_vfs, sqlite3_vfs_find, sqlite3_vfs_register,
};

/// The VFS's name, for `database.sqlite_vfs`.
pub const NAME: &str = "rackd-faulty";

/// [`NAME`] as SQLite reads it.
const NAME_C: &CStr = c"rackd-faulty";

/// Whether the writes to one database's WAL fail, and how many did.
#[derive(Debug, Default)]
pub struct Switch {
    armed: AtomicBool,
    injected: AtomicU64,
}

impl Switch {
    /// Every write to the WAL fails from now on, until [`Switch::disarm`].
    pub fn arm(&self) {
        self.armed.store(true, Ordering::SeqCst);
    }

    /// Writes go through again.
    pub fn disarm(&self) {
        self.armed.store(false, Ordering::SeqCst);
    }

    /// The writes failed so far.
    pub fn injected(&self) -> u64 {
        self.injected.load(Ordering::SeqCst)
    }
}

/// Registers the VFS (once a process) and returns the switch of the database at `path`,
/// whose folder exists. The WAL files of other databases opened through the VFS are never
/// faulted, so tests running beside each other cannot trip one another.
pub fn watch(path: &Path) -> Arc<Switch> {
    register();
    // SQLite names a file by its full path with the symbolic links resolved.
    let folder = path.parent().expect("a database file in a folder");
    let folder = std::fs::canonicalize(folder).expect("the database's folder");
    let path = folder.join(path.file_name().expect("a database file's name"));
    let switch = Arc::new(Switch::default());
    watched().lock().unwrap().push((path, switch.clone()));
    switch
}

/// The databases watched, each with its switch.
fn watched() -> &'static Mutex<Vec<(PathBuf, Arc<Switch>)>> {
    static WATCHED: Mutex<Vec<(PathBuf, Arc<Switch>)>> = Mutex::new(Vec::new());
    &WATCHED
}

/// The switch of the WAL file SQLite opens as `name` with `flags`, if its database is watched.
fn switch_of(name: *const c_char, flags: c_int) -> Option<Arc<Switch>> {
    if flags & SQLITE_OPEN_WAL == 0 || name.is_null() {
        return None;
    }
    // SAFETY: SQLite passes a WAL file's name as a NUL-terminated string.
    let name = unsafe { CStr::from_ptr(name) }.to_str().ok()?;
    let database = Path::new(name.strip_suffix("-wal")?);
    let watched = watched().lock().unwrap();
    watched.iter().find(|(path, _)| path == database).map(|(_, switch)| switch.clone())
}

/// SQLite's default VFS, which this one wraps.
static REAL: AtomicPtr<sqlite3_vfs> = AtomicPtr::new(std::ptr::null_mut());

/// Registers the VFS under [`NAME`], once.
fn register() {
    static DONE: OnceLock<()> = OnceLock::new();
    DONE.get_or_init(|| {
        // SAFETY: with a null name, SQLite (initialising itself first) returns its default
        // VFS, which lives as long as the process.
        let real = unsafe { sqlite3_vfs_find(std::ptr::null()) };
        assert!(!real.is_null(), "SQLite has a default VFS");
        REAL.store(real, Ordering::SeqCst);
        // SAFETY: `real` points to a valid VFS; the copy is leaked, as SQLite keeps it for
        // the rest of the process.
        let mut vfs = unsafe { std::ptr::read(real) };
        vfs.zName = NAME_C.as_ptr();
        vfs.szOsFile = (HEADER + unsafe { (*real).szOsFile } as usize) as c_int;
        vfs.pNext = std::ptr::null_mut();
        vfs.xOpen = Some(open);
        let vfs = Box::leak(Box::new(vfs));
        // SAFETY: a complete VFS that outlives every connection; not made the default.
        let rc = unsafe { sqlite3_vfs_register(vfs, 0) };
        assert_eq!(rc, SQLITE_OK, "registering the VFS");
    });
}

/// What SQLite allocates for each file opened through this VFS: this header, then the
/// real file (the default VFS's `szOsFile` bytes), which every method is forwarded to.
#[repr(C)]
struct File {
    /// First, as SQLite reads it: `pMethods`.
    base: sqlite3_file,
    /// The switch, for a watched database's WAL.
    switch: Option<Arc<Switch>>,
}

/// The header's size, a multiple of 8, so the real file after it is aligned as SQLite
/// aligns the whole.
const HEADER: usize = std::mem::size_of::<File>();

/// The real file behind `file`.
///
/// SAFETY: `file` is one SQLite allocated for this VFS (`szOsFile` bytes).
unsafe fn real(file: *mut sqlite3_file) -> *mut sqlite3_file {
    unsafe { file.cast::<u8>().add(HEADER).cast() }
}

/// `xOpen`: the real file opened behind the header, with the methods below if it was.
unsafe extern "C" fn open(
    _vfs: *mut sqlite3_vfs,
    name: *const c_char,
    file: *mut sqlite3_file,
    flags: c_int,
    out_flags: *mut c_int,
) -> c_int {
    let vfs = REAL.load(Ordering::SeqCst);
    // SAFETY: SQLite hands `file` with `szOsFile` bytes; the default VFS opens its own file
    // in the part after the header, given its own VFS pointer.
    unsafe {
        let inner = real(file);
        let rc = ((*vfs).xOpen.expect("xOpen"))(vfs, name, inner, flags, out_flags);
        if (*inner).pMethods.is_null() {
            // Nothing to close: SQLite calls no method of a file without methods.
            (*file).pMethods = std::ptr::null();
            return rc;
        }
        std::ptr::write(&raw mut (*file.cast::<File>()).switch, switch_of(name, flags));
        (*file).pMethods = &METHODS;
        rc
    }
}

/// `xWrite`: fails while the file's switch is armed, else forwarded.
unsafe extern "C" fn write(
    file: *mut sqlite3_file,
    buf: *const c_void,
    amount: c_int,
    offset: sqlite3_int64,
) -> c_int {
    // SAFETY: `file` was opened by [`open`], so its header is initialised.
    let switch = unsafe { &(*file.cast::<File>()).switch };
    if let Some(switch) = switch.as_ref().filter(|s| s.armed.load(Ordering::SeqCst)) {
        switch.injected.fetch_add(1, Ordering::SeqCst);
        return SQLITE_IOERR_WRITE;
    }
    // SAFETY: forwarded to the real file, which was opened.
    unsafe {
        let inner = real(file);
        ((*(*inner).pMethods).xWrite.expect("xWrite"))(inner, buf, amount, offset)
    }
}

/// `xClose`: the real file closed, the header's switch let go.
unsafe extern "C" fn close(file: *mut sqlite3_file) -> c_int {
    // SAFETY: opened by [`open`]; SQLite calls no method after this one.
    unsafe {
        let inner = real(file);
        let rc = ((*(*inner).pMethods).xClose.expect("xClose"))(inner);
        std::ptr::drop_in_place(&raw mut (*file.cast::<File>()).switch);
        rc
    }
}

/// A method that calls the real file's own. The default VFS's files have every method
/// (their `iVersion` is 3, as this one's).
macro_rules! forward {
    ($name:ident, $method:ident, ($($arg:ident: $ty:ty),*) $(-> $ret:ty)?) => {
        unsafe extern "C" fn $name(file: *mut sqlite3_file $(, $arg: $ty)*) $(-> $ret)? {
            // SAFETY: `file` was opened by [`open`], so the real file behind it was too.
            unsafe {
                let inner = real(file);
                ((*(*inner).pMethods).$method.expect(stringify!($method)))(inner $(, $arg)*)
            }
        }
    };
}

forward!(read, xRead, (buf: *mut c_void, amount: c_int, offset: sqlite3_int64) -> c_int);
forward!(truncate, xTruncate, (size: sqlite3_int64) -> c_int);
forward!(sync, xSync, (flags: c_int) -> c_int);
forward!(file_size, xFileSize, (size: *mut sqlite3_int64) -> c_int);
forward!(lock, xLock, (level: c_int) -> c_int);
forward!(unlock, xUnlock, (level: c_int) -> c_int);
forward!(check_reserved_lock, xCheckReservedLock, (out: *mut c_int) -> c_int);
forward!(file_control, xFileControl, (op: c_int, arg: *mut c_void) -> c_int);
forward!(sector_size, xSectorSize, () -> c_int);
forward!(device_characteristics, xDeviceCharacteristics, () -> c_int);
forward!(shm_map, xShmMap, (page: c_int, size: c_int, extend: c_int, out: *mut *mut c_void) -> c_int);
forward!(shm_lock, xShmLock, (offset: c_int, n: c_int, flags: c_int) -> c_int);
forward!(shm_barrier, xShmBarrier, ());
forward!(shm_unmap, xShmUnmap, (delete: c_int) -> c_int);
forward!(fetch, xFetch, (offset: sqlite3_int64, amount: c_int, out: *mut *mut c_void) -> c_int);
forward!(unfetch, xUnfetch, (offset: sqlite3_int64, page: *mut c_void) -> c_int);

/// The methods of every file opened through this VFS.
static METHODS: sqlite3_io_methods = sqlite3_io_methods {
    iVersion: 3,
    xClose: Some(close),
    xRead: Some(read),
    xWrite: Some(write),
    xTruncate: Some(truncate),
    xSync: Some(sync),
    xFileSize: Some(file_size),
    xLock: Some(lock),
    xUnlock: Some(unlock),
    xCheckReservedLock: Some(check_reserved_lock),
    xFileControl: Some(file_control),
    xSectorSize: Some(sector_size),
    xDeviceCharacteristics: Some(device_characteristics),
    xShmMap: Some(shm_map),
    xShmLock: Some(shm_lock),
    xShmBarrier: Some(shm_barrier),
    xShmUnmap: Some(shm_unmap),
    xFetch: Some(fetch),
    xUnfetch: Some(unfetch),
};
