//! The CLIP tokenizer against the official OpenCLIP tokenizer's ids on a list of prompts
//! (fixture made by `scripts/make_clip_fixture.py`).

use semantics::clip::{Tokenizer, CONTEXT_LENGTH};

#[derive(serde::Deserialize)]
struct Fixture {
    context_length: usize,
    prompts: Vec<String>,
    ids: Vec<Vec<u32>>,
}

#[test]
fn tokenizer_matches_open_clip() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/clip/tokens.json"
    );
    let text = std::fs::read_to_string(path).expect("fixture tokens.json");
    let fixture: Fixture = serde_json::from_str(&text).expect("valid tokens.json");
    assert_eq!(fixture.context_length, CONTEXT_LENGTH);
    assert!(fixture.prompts.len() >= 10);
    let tok = Tokenizer::new().unwrap();
    for (prompt, expected) in fixture.prompts.iter().zip(&fixture.ids) {
        assert_eq!(
            &tok.tokenize(prompt, fixture.context_length),
            expected,
            "prompt {prompt:?}"
        );
    }
}
