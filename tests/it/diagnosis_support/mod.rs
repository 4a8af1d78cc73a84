//! Reading a diagnosis's JSON (`rpkm diagnose --json`) the way the tests check it.

/// The candidate `effect` of diagnosis `d`, or a failure naming it.
pub fn candidate<'d>(d: &'d serde_json::Value, effect: &str) -> &'d serde_json::Value {
    d["candidates"]
        .as_array()
        .expect("candidates")
        .iter()
        .find(|c| c["effect"] == effect)
        .unwrap_or_else(|| panic!("{effect} among the candidates"))
}

/// The effect parameter `name` of a list of them (a diagnosis's `effect_values`, a
/// calibration's `effects`): its value and σ, or a failure naming what is missing.
pub fn effect_value(list: &serde_json::Value, name: &str) -> (f64, f64) {
    let p = list
        .as_array()
        .expect("effect parameters")
        .iter()
        .find(|e| e["name"] == name)
        .unwrap_or_else(|| panic!("the effect parameter {name}"));
    (
        p["value"].as_f64().expect("value"),
        p["sigma"].as_f64().expect("σ"),
    )
}

/// The fitted parameter `name` of the candidate `effect` of diagnosis `d`: its value, σ and
/// unit, or a failure naming what is missing.
pub fn candidate_param(d: &serde_json::Value, effect: &str, name: &str) -> (f64, f64, String) {
    let p = candidate(d, effect)["params"]
        .as_array()
        .expect("params")
        .iter()
        .find(|p| p["name"] == name)
        .unwrap_or_else(|| panic!("{effect}'s {name}"));
    (
        p["value"].as_f64().expect("value"),
        p["sigma"].as_f64().expect("σ"),
        p["unit"].as_str().expect("unit").to_owned(),
    )
}
