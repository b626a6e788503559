//! Files of rackd's own: every file rackd writes (the archive's days, alarm captures,
//! `rackd plc --capture`, a new SQLite database) is created here, so that each is made the
//! same careful way.
//!
//! Decisions:
//! - **Created, never opened**: a file is created with `O_CREAT | O_EXCL` ([`create`]), so
//!   a name that exists, a symbolic link planted there included (`O_EXCL` never follows
//!   one, as POSIX says), is refused instead of being written through. The folders on the
//!   way are the site's (a configured path), and are followed.
//! - **The owner's alone**: mode `0600` (less the process's umask). Archives hold every
//!   job's history, captures every value a machine held and was sent.
//! - **Written beside, then published without replacing** ([`Draft`]): a file others read
//!   whole (a download, a reader of the archive) is written under a unique temporary name
//!   (`NAME.PID-RANDOM.part`, in the same folder), synced, then given its name with a hard
//!   link, which fails when the name exists, and the temporary name is removed, and the
//!   folder synced. Two writers that choose the same name (the hourly archive and
//!   `rackd db archive` into one folder) so never overwrite each other: the second is told
//!   the name is taken and takes the next ([`Draft::publish`] tries names in order). A
//!   hard link rather than `renameat2(RENAME_NOREPLACE)`: it is in `std`, on every Unix
//!   filesystem rackd's folders are on; a crash between the link and the removal leaves a
//!   `.part` file, never a missing or half file. A filesystem without hard links (FAT) is
//!   refused with that said.
//! - A draft dropped before it is published removes its temporary file.

use std::fs::File;
use std::io;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

/// The permissions of every file rackd creates: its owner's alone.
pub const MODE: u32 = 0o600;

/// Creates `path`, a new file of rackd's own: refused if anything is there (a file, a
/// symbolic link), readable and writable by its owner alone.
pub fn create(path: &Path) -> io::Result<File> {
    std::fs::OpenOptions::new().write(true).create_new(true).mode(MODE).open(path)
}

/// A file being written under a temporary name in its folder, until [`Draft::publish`]
/// gives it its name.
#[derive(Debug)]
pub struct Draft {
    temp: PathBuf,
    file: File,
    published: bool,
}

impl Draft {
    /// A new temporary file beside `path` (in its folder, its name starting with `path`'s)
    /// for a file to be published as `path` (or a name like it).
    pub fn beside(path: &Path) -> io::Result<Draft> {
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        loop {
            let temp = path.with_file_name(format!(
                "{name}.{}-{:08x}.part",
                std::process::id(),
                rand::random::<u32>()
            ));
            match create(&temp) {
                Ok(file) => return Ok(Draft { temp, file, published: false }),
                // Another draft's name (or a leftover): draw again.
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(e),
            }
        }
    }

    /// The file, to write to (`&File` is `Write`).
    pub fn file(&self) -> &File {
        &self.file
    }

    /// Syncs the file and gives it the first of `names` (each in the draft's folder) that
    /// is free, never replacing a file; then syncs the folder. Answers the name taken; an
    /// `AlreadyExists` error when every name is taken.
    pub fn publish(mut self, names: impl IntoIterator<Item = PathBuf>) -> io::Result<PathBuf> {
        self.file.sync_all()?;
        for name in names {
            match std::fs::hard_link(&self.temp, &name) {
                Ok(()) => {
                    self.published = true;
                    std::fs::remove_file(&self.temp)?;
                    if let Some(dir) = name.parent().filter(|d| !d.as_os_str().is_empty()) {
                        File::open(dir)?.sync_all()?;
                    }
                    return Ok(name);
                }
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                // EPERM from link(2): the filesystem makes no hard links (FAT).
                Err(e) if e.raw_os_error() == Some(1) || e.kind() == io::ErrorKind::Unsupported => {
                    let why = format!("{e} (rackd names its files with hard links: is the folder on FAT?)");
                    return Err(io::Error::new(e.kind(), why));
                }
                Err(e) => return Err(e),
            }
        }
        Err(io::Error::new(io::ErrorKind::AlreadyExists, "every name is taken"))
    }
}

impl Drop for Draft {
    fn drop(&mut self) {
        if !self.published {
            let _ = std::fs::remove_file(&self.temp);
        }
    }
}

#[cfg(test)]
mod tests {
    use std::io::{Read, Write};
    use std::os::unix::fs::PermissionsExt;

    use super::*;

    fn mode(path: &Path) -> u32 {
        std::fs::metadata(path).unwrap().permissions().mode() & 0o777
    }

    #[test]
    fn a_new_file_is_the_owners_and_nothing_there_is_written_through() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("new");
        create(&file).unwrap().write_all(b"mine").unwrap();
        assert_eq!(mode(&file) & 0o077, 0, "{:o}", mode(&file));
        // A file, a link to a file, a dangling link: all refused, none written.
        let victim = dir.path().join("victim");
        std::fs::write(&victim, "theirs").unwrap();
        std::os::unix::fs::symlink(&victim, dir.path().join("link")).unwrap();
        std::os::unix::fs::symlink(dir.path().join("nowhere"), dir.path().join("dangling")).unwrap();
        for name in ["new", "victim", "link", "dangling"] {
            let e = create(&dir.path().join(name)).unwrap_err();
            assert_eq!(e.kind(), io::ErrorKind::AlreadyExists, "{name}");
        }
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "theirs");
        assert!(!dir.path().join("nowhere").exists());
    }

    #[test]
    fn a_draft_takes_the_first_free_name_and_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let taken = dir.path().join("day.gz");
        std::fs::write(&taken, "first").unwrap();
        std::os::unix::fs::symlink(dir.path().join("nowhere"), dir.path().join("day.2.gz")).unwrap();
        let draft = Draft::beside(&dir.path().join("day.gz")).unwrap();
        draft.file().write_all(b"second").unwrap();
        let names = ["day.gz", "day.2.gz", "day.3.gz"].map(|n| dir.path().join(n));
        let name = draft.publish(names).unwrap();
        assert_eq!(name, dir.path().join("day.3.gz"));
        assert_eq!(std::fs::read_to_string(&taken).unwrap(), "first", "never replaced");
        let mut text = String::new();
        File::open(&name).unwrap().read_to_string(&mut text).unwrap();
        assert_eq!(text, "second");
        assert_eq!(mode(&name) & 0o077, 0);
        let mut left: Vec<_> =
            std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        left.sort();
        assert_eq!(left, ["day.2.gz", "day.3.gz", "day.gz"]);

        // Every name taken: an error, and the draft's file is gone.
        let draft = Draft::beside(&dir.path().join("day.gz")).unwrap();
        let e = draft.publish([dir.path().join("day.gz")]).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::AlreadyExists);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
    }
}
