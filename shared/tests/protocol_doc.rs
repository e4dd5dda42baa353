//! docs/protocol.md against the code: an outsider copies the schema string, the hashes
//! and the iceoryx2 version from that page, so they must be this build's.

use oils_shared::c_abi::{FSW_ABI_SCHEMA, FSW_ABI_VERSION, FSW_LAYOUT_HASH};
use oils_shared::{PROTOCOL_VERSION, SCHEMA, SCHEMA_HASH};
use std::path::Path;

fn read(rel: &str) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    std::fs::read_to_string(root.join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

#[test]
fn doc_gives_the_schema_string_and_both_hashes() {
    let doc = read("docs/protocol.md");
    assert!(doc.starts_with(&format!("# Wire protocol, version {PROTOCOL_VERSION}\n")));
    // The schema block: one entry per line, in order, together exactly SCHEMA.
    let block = doc
        .split("```text\n")
        .nth(1)
        .and_then(|b| b.split("```").next())
        .expect("a ```text block with the schema string");
    assert_eq!(
        block.replace('\n', ""),
        SCHEMA,
        "docs/protocol.md's schema string"
    );
    assert!(
        doc.contains(&format!("**`{SCHEMA_HASH:#018x}`**")),
        "docs/protocol.md must give the schema hash {SCHEMA_HASH:#018x}"
    );
    assert!(
        doc.contains(&format!("(`{SCHEMA_HASH:#018x}`")),
        "the oils.schema_hash attribute's value"
    );
    assert!(
        doc.contains(&format!("**`{FSW_LAYOUT_HASH:#018x}`**")),
        "layout hash"
    );
    assert!(
        doc.contains(&format!("`{}`", FSW_ABI_SCHEMA)),
        "FswConfig schema"
    );
    assert!(doc.contains(&format!("## The C ABI (version {FSW_ABI_VERSION})")));
}

#[test]
fn doc_gives_the_iceoryx2_version_in_use() {
    let lock = read("Cargo.lock");
    let version = lock
        .split("[[package]]")
        .find(|p| p.contains("\nname = \"iceoryx2\"\n"))
        .and_then(|p| p.split("\nversion = \"").nth(1))
        .and_then(|v| v.split('"').next())
        .expect("iceoryx2 in Cargo.lock");
    let doc = read("docs/protocol.md");
    assert!(
        doc.contains(&format!("iceoryx2 **{version}**")),
        "docs: iceoryx2 {version}"
    );
    assert!(
        doc.contains(&format!("iceoryx2=={version}")),
        "docs: the pip pin"
    );
    assert_eq!(oils_shared::service::ICEORYX2_VERSION, version);
    let script = read("tools/python-e2e.sh");
    assert!(
        script.contains(&format!("ICEORYX2_VERSION={version}")),
        "python-e2e.sh pin"
    );
}
