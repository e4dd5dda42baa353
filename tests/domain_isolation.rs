//! oils runs in an iceoryx2 domain of its own (a 0700 directory of the user, a prefix of
//! its own, a global segment made 0600): another local user can neither break a run nor,
//! as with iceoryx2's world-writable default global segment, every later run.
//!
//! The machine under test runs as root: the attacker is `nobody` (setpriv), and the whole
//! scene plays in a private mount namespace with a /dev/shm of its own, so the attack on
//! iceoryx2's default segment cannot touch other programs of this machine.

mod common;
use common::*;
use std::process::Command;

fn have(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

/// Why the scene cannot be played here, if it cannot.
fn cannot_play() -> Option<String> {
    // SAFETY: geteuid cannot fail.
    if unsafe { libc::geteuid() } != 0 {
        return Some("needs root, to act as `nobody` and to mount a private /dev/shm".into());
    }
    for tool in ["setpriv", "unshare", "mount"] {
        if !have(tool) {
            return Some(format!("`{tool}` is not installed"));
        }
    }
    let nobody = Command::new("id").arg("nobody").output();
    if !nobody.map(|o| o.status.success()).unwrap_or(false) {
        return Some("there is no user `nobody`".into());
    }
    None
}

const SCENE: &str = r#"
set -u
mount -t tmpfs -o mode=1777 tmpfs /dev/shm || { echo "CANNOT mount a private /dev/shm"; exit 77; }
cd /
AS_NOBODY="setpriv --reuid=65534 --regid=65534 --clear-groups"
TAIL=9204dd183d1c4d8e1ff592a30766ffa6765aa8b5_node.0_10_0.global_mgmt

# The old attack: iceoryx2's default global segment, world-writable, overwritten.
$AS_NOBODY sh -c "printf 'garbage garbage!' > /dev/shm/iox2_$TAIL && chmod 666 /dev/shm/iox2_$TAIL" \
  && echo "DEFAULT SEGMENT OVERWRITTEN"

# The attacker keeps at every oils file it can see while the runs go.
$AS_NOBODY sh -c '
  while [ ! -e "$STOP" ]; do
    for f in /dev/shm/oils_*; do
      [ -e "$f" ] || continue
      echo "SAW $f"
      # (nocreat, unlink: a file iceoryx2 removed meanwhile is no success)
      printf "garbage garbage garbage garbage" \
        | dd of="$f" conv=notrunc,nocreat status=none 2>/dev/null && echo "WROTE $f"
      dd of="$f" conv=nocreat count=0 status=none </dev/null 2>/dev/null && echo "TRUNCATED $f"
      unlink "$f" 2>/dev/null && echo "REMOVED $f"
    done
    ls "$OILS_IOX2_ROOT" >/dev/null 2>&1 && echo "LISTED the domain"
    touch "$OILS_IOX2_ROOT/intruder" 2>/dev/null && echo "CREATED in the domain"
    cat "$OILS_IOX2_ROOT/token" 2>/dev/null && echo "READ the token"
    sleep 0.02
  done' > "$ATTACK_LOG" 2>&1 &
ATTACKER=$!

"$OILS" run --no-log --report "$REP1" >/dev/null 2>"$REP1.err"; echo "RUN1 EXIT $?"
touch "$STOP"; wait $ATTACKER

# A squatter who learnt the domain's segment name takes it while it is absent.
seg=$(ls /dev/shm/oils_*"$TAIL")
rm -f "$seg"
$AS_NOBODY sh -c "printf 'garbage garbage!' > $seg && chmod 666 $seg" && echo "SQUATTED $seg"
"$OILS" run --no-log --report "$REP2" >/dev/null 2>"$REP2.err"; echo "RUN2 EXIT $?"
ls -l /dev/shm
"#;

#[test]
fn an_unprivileged_user_cannot_break_a_run_nor_later_ones() {
    if let Some(why) = cannot_play() {
        eprintln!("SKIPPED an_unprivileged_user_cannot_break_a_run_nor_later_ones: {why}");
        return;
    }
    let dir = scratch("domain-isolation");
    let domain = dir.join("domain");
    let (rep1, rep2) = (dir.join("run1.json"), dir.join("run2.json"));
    let attack_log = dir.join("attack.log");
    // The digest the run must have: the same descent in process, no IPC at all.
    let inproc = dir.join("inproc.json");
    let out = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--no-log",
        "--report",
        inproc.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let expected = report(&inproc)["digest"].as_str().unwrap().to_string();

    let out = Command::new("unshare")
        .args(["--mount", "--propagation", "private", "sh", "-c", SCENE])
        .env("OILS", env!("CARGO_BIN_EXE_oils"))
        .env("OILS_IOX2_ROOT", &domain)
        .env("REP1", &rep1)
        .env("REP2", &rep2)
        .env("ATTACK_LOG", &attack_log)
        .env("STOP", dir.join("stop"))
        .output()
        .unwrap();
    let scene = text(&out);
    if out.status.code() == Some(77) {
        eprintln!("SKIPPED an_unprivileged_user_cannot_break_a_run_nor_later_ones: {scene}");
        return;
    }
    let attack = std::fs::read_to_string(&attack_log).unwrap_or_default();
    let stdout = String::from_utf8_lossy(&out.stdout);
    // The old attack happened, and did not matter.
    assert!(stdout.contains("DEFAULT SEGMENT OVERWRITTEN"), "{scene}");
    // The attacker saw oils's shared memory, and could do nothing to it or the domain.
    assert!(attack.contains("SAW /dev/shm/oils_"), "{attack}\n{scene}");
    for act in ["WROTE", "TRUNCATED", "REMOVED", "LISTED", "CREATED", "READ"] {
        assert!(!attack.contains(act), "the attacker {act}:\n{attack}");
    }
    assert!(stdout.contains("RUN1 EXIT 0"), "{scene}");
    let r1 = report(&rep1);
    assert_eq!(r1["outcome"], "landed", "{r1}");
    assert_eq!(r1["digest"], expected.as_str(), "{r1}");
    // The squatted segment name: the domain draws a new one and says so.
    assert!(stdout.contains("SQUATTED"), "{scene}");
    assert!(
        stdout.contains("RUN2 EXIT 0"),
        "{scene}\n{}",
        std::fs::read_to_string(rep2.with_extension("json.err")).unwrap_or_default()
    );
    let r2 = report(&rep2);
    assert_eq!(r2["digest"], expected.as_str());
    assert!(
        r2["warnings"].to_string().contains("a new one was drawn"),
        "{}",
        r2["warnings"]
    );
    let _ = std::fs::remove_dir_all(&dir);
}
