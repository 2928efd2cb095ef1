//! `VISION_TOUCH_IPC_ROOT` moves the stack's iceoryx2 records into a
//! directory of the deployment's choosing (a systemd `RuntimeDirectory`),
//! and processes under it see one another there and not under the default.
//! One test in its own binary: the variable is read once per process.

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use shared_mem_schema::transport::{self, IPC_ROOT_ENV};
use shared_mem_schema::{Header, Message, PolicyAction};

#[test]
fn nodes_and_services_live_under_the_configured_root() {
    let dir = std::env::temp_dir().join(format!("vt-ipc-root-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // SAFETY: the only test of this binary, before anything reads the
    // environment or starts a thread of its own.
    unsafe { std::env::set_var(IPC_ROOT_ENV, &dir) };
    let config = transport::stack_config().unwrap();
    assert_eq!(
        config.global.root_path().as_str(),
        format!("{}/", dir.display())
    );

    let ns = format!("test-root-{}", std::process::id());
    let node = transport::create_node("ipc-root-test").unwrap();
    let publisher = transport::publisher::<PolicyAction>(&node, &ns).unwrap();
    let other = transport::create_node("ipc-root-peer").unwrap();
    let subscriber = transport::subscriber::<PolicyAction>(&other, &ns).unwrap();
    let mut a = *PolicyAction::boxed_zeroed();
    a.header = Header::new(7, 0, 0, 1);
    transport::send(&publisher, &a).unwrap();
    let mut seen = Vec::new();
    transport::drain(&subscriber, |m| seen.push(m.header.seq)).unwrap();
    assert_eq!(seen, vec![7], "a message between two nodes under the root");

    // The records are under the root, and a process on the default root
    // does not see these nodes.
    let files = walk(&dir);
    assert!(!files.is_empty(), "nothing written under {}", dir.display());
    let names = |cfg: &Config| {
        let mut v = Vec::new();
        let _ = Node::<ipc::Service>::list(cfg, |state| {
            if let NodeState::Alive(view) = state
                && let Some(d) = view.details()
            {
                v.push(d.name().as_str().to_owned());
            }
            CallbackProgression::Continue
        });
        v
    };
    assert!(names(config).iter().any(|n| n == "ipc-root-test"));
    let default = Config::default();
    assert!(!names(&default).iter().any(|n| n == "ipc-root-test"));
    drop((publisher, subscriber, node, other));
    let _ = std::fs::remove_dir_all(&dir);
}

fn walk(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}
