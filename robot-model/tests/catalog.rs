//! Robots named by input the process does not trust: the built-in ones, or
//! regular, bounded URDF files inside the configured directory, and nothing
//! else (no absolute paths, no `..`, no symbolic link out, no FIFO, no
//! device, no huge file).

use robot_model::descriptions::{IIWA14_URDF, RobotCatalog};
use robot_model::urdf::MAX_URDF_BYTES;
use robot_model::{LoadOptions, Model};
use std::os::unix::fs::symlink;

fn refused(catalog: &RobotCatalog, name: &str) -> String {
    match catalog.load(name) {
        Ok(_) => panic!("{name:?} was loaded"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn without_a_directory_only_builtin_robots_load() {
    let c = RobotCatalog::builtin_only();
    assert_eq!(c.load("iiwa14").unwrap().nv(), 7);
    assert_eq!(c.load("panda").unwrap().nv(), 7);
    for name in ["/etc/passwd", "/dev/zero", "robot.urdf", "../iiwa14"] {
        let e = refused(&c, name);
        assert!(e.contains("no robot directory is configured"), "{e}");
    }
}

#[test]
fn a_directory_serves_its_regular_files_and_nothing_outside() {
    let scratch = test_support::scratch_dir("catalog");
    let root = scratch.path();
    let dir = root.join("robots");
    std::fs::create_dir_all(dir.join("sub")).unwrap();
    std::fs::write(dir.join("arm.urdf"), IIWA14_URDF).unwrap();
    std::fs::write(dir.join("sub/arm.urdf"), IIWA14_URDF).unwrap();
    std::fs::write(root.join("outside.urdf"), IIWA14_URDF).unwrap();
    symlink(root.join("outside.urdf"), dir.join("out.urdf")).unwrap();
    symlink("/dev/zero", dir.join("zero.urdf")).unwrap();
    symlink(dir.join("arm.urdf"), dir.join("alias.urdf")).unwrap();
    let fifo = std::ffi::CString::new(dir.join("fifo.urdf").to_str().unwrap()).unwrap();
    // SAFETY: a valid C string.
    assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o600) }, 0);
    let big = std::fs::File::create(dir.join("big.urdf")).unwrap();
    big.set_len(MAX_URDF_BYTES + 1).unwrap();

    let c = RobotCatalog::with_dir(&dir).unwrap();
    for ok in ["arm.urdf", "sub/arm.urdf", "alias.urdf", "iiwa14"] {
        assert_eq!(c.load(ok).unwrap().nv(), 7, "{ok}");
    }
    for (name, why) in [
        ("../outside.urdf", "plain relative path"),
        ("sub/../arm.urdf", "plain relative path"),
        ("/etc/passwd", "plain relative path"),
        ("", "plain relative path"),
        ("out.urdf", "leads out of the robot directory"),
        ("zero.urdf", "leads out of the robot directory"),
        ("missing.urdf", "no such file"),
        ("fifo.urdf", "not a regular file"),
        ("big.urdf", "allowed"),
    ] {
        let e = refused(&c, name);
        assert!(e.contains(why), "{name}: {e}");
    }
}

#[test]
fn a_urdf_file_is_a_bounded_regular_file_even_for_the_operator() {
    // A FIFO would block a plain read until a writer came; /dev/zero would
    // fill the memory.
    let scratch = test_support::scratch_dir("catalog-op");
    let fifo_path = scratch.path().join("fifo.urdf");
    let fifo = std::ffi::CString::new(fifo_path.to_str().unwrap()).unwrap();
    // SAFETY: a valid C string.
    assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o600) }, 0);
    for path in [fifo_path.as_path(), std::path::Path::new("/dev/zero")] {
        let e = Model::from_urdf_file(path, &LoadOptions::default()).unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
    }
}
