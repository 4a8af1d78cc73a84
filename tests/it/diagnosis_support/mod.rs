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
    value_and_sigma(param_in(list, name, "the effect parameters"))
}

/// A parameter's value and σ.
fn value_and_sigma(p: &serde_json::Value) -> (f64, f64) {
    (
        p["value"].as_f64().expect("value"),
        p["sigma"].as_f64().expect("σ"),
    )
}

/// The parameter `name` of a list of them, or a failure naming it and `whose` list.
fn param_in<'l>(list: &'l serde_json::Value, name: &str, whose: &str) -> &'l serde_json::Value {
    list.as_array()
        .unwrap_or_else(|| panic!("{whose}"))
        .iter()
        .find(|p| p["name"] == name)
        .unwrap_or_else(|| panic!("{name} among {whose}"))
}

/// The fitted parameter `name` of the candidate `effect` of diagnosis `d`: its value, σ and
/// unit, or a failure naming what is missing.
pub fn candidate_param(d: &serde_json::Value, effect: &str, name: &str) -> (f64, f64, String) {
    let p = param_in(&candidate(d, effect)["params"], name, effect);
    let (value, sigma) = value_and_sigma(p);
    (value, sigma, p["unit"].as_str().expect("unit").to_owned())
}
