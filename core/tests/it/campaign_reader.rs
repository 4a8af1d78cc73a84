//! The campaign CSV reader against the spec's contract (section "Campaign CSV"): a valid file
//! with every instrument, and each error kind with its line and column.
#![expect(
    clippy::float_cmp,
    reason = "exact values: parsed, copied or computed without rounding"
)]

use rpkm_core::campaign::{Campaign, CampaignError, Instrument, MeasuredPose};

/// A valid campaign with every instrument. Line numbers matter to the tests below:
/// line 3 is the header, data rows are lines 4..=19 (t = line - 4).
const VALID: &str = "\
# rpkm campaign: every instrument
# nominal parameters, simulated
t,setup,instrument,reset,q1,q2,q3,q4,f1,f2,f3,f4,follower,x,y,r,psi,temp_machine,temp_guide1
0,LT1,lt,1,2611.0556,2611.0556,788.9444,788.9444,10,-20,30,-40,,0,0,,,20.5,21
1,LT1,lt,0,2600,2600.5,780,780.25,1,2,3,4,,-10.5,12.25,,,20.6,
2,K1,kgm,1,2611,2611,789,789,0,0,0,0,,,,,,20.7,21.1
3,K1,kgm,0,2541,2541,719,719,0,0,0,0,,70,-70,,,,
4,D1,dbb,1,2611,2611,789,789,0,0,0,0,,,,0,,,
5,D1,dbb,0,2661,2661,839,839,0,0,0,0,,,,150.0012,,,
6,LX1,li_x,1,2611,2611,789,789,0,0,0,0,,0,,,,,
7,LX1,li_x,0,2611,2611,789,789,0,0,0,0,,15.0003,,,,,
8,LY1,li_y,1,2611,2611,789,789,0,0,0,0,,,0,,,,
9,LY1,li_y,0,2636,2636,814,814,0,0,0,0,,,25.001,,,,
10,P1,li_psi,1,2611,2611,789,789,0,0,0,0,,,,,,,
11,P1,li_psi,0,2700,2700,878,878,0,0,0,0,,,,,1.5e-6,,
12,S1,self,0,2611,2611.414,788.359,789,5,0,0,-5,23,,,,,,
13,C1,circle,0,2711,2711,889,889,0,0,0,0,,,,100.002,,,
14,N,none,0,2611,2611,789,789,0,0,0,0,,,,,,19.5,19.75
15,C1,circle,0,2511,2511,689,689,0,0,0,0,,,,99.998,,,
";

const FILE: &str = "campaign.csv";

fn parse(text: &str) -> Result<Campaign, CampaignError> {
    Campaign::parse(text, FILE)
}

/// `text` with field `column` (1-based) of line `line` (1-based) replaced by `value`.
fn with_field(text: &str, line: usize, column: usize, value: &str) -> String {
    edit_line(text, line, |l| {
        let mut fields: Vec<&str> = l.split(',').collect();
        fields[column - 1] = value;
        fields.join(",")
    })
}

fn edit_line(text: &str, line: usize, edit: impl Fn(&str) -> String) -> String {
    text.lines()
        .enumerate()
        .map(|(i, l)| if i + 1 == line { edit(l) } else { l.to_owned() })
        .map(|l| l + "\n")
        .collect()
}

/// The error of a text that must not parse, with its location checked.
fn error_at(text: &str, line: Option<usize>, column: Option<usize>) -> CampaignError {
    let e = parse(text).expect_err("the edited file must be rejected");
    assert_eq!(e.file(), FILE, "{e}");
    assert_eq!(e.line(), line, "{e}");
    assert_eq!(e.column(), column, "{e}");
    let prefix = match (line, column) {
        (Some(l), Some(c)) => format!("{FILE}:{l}:{c}"),
        (Some(l), None) => format!("{FILE}:{l}: "),
        _ => format!("{FILE}: "),
    };
    assert!(e.to_string().starts_with(&prefix), "{e}");
    e
}

#[test]
fn every_instrument_parses_to_the_right_values() {
    let c = parse(VALID).expect("valid");
    assert_eq!(c.source, FILE);
    assert_eq!(
        c.comments,
        [
            "rpkm campaign: every instrument",
            "nominal parameters, simulated"
        ]
    );
    assert_eq!(c.covariate_names, ["temp_machine", "temp_guide1"]);
    assert_eq!(c.poses.len(), 16);
    let lt = &c.poses[1];
    assert_eq!(
        *lt,
        MeasuredPose {
            t: 1.0,
            setup: "LT1".into(),
            instrument: Instrument::Lt,
            reset: false,
            q: [2600.0, 2600.5, 780.0, 780.25],
            f: [1.0, 2.0, 3.0, 4.0],
            follower: [false; 4],
            x: Some(-10.5),
            y: Some(12.25),
            r: None,
            psi: None,
            covariates: vec![Some(20.6), None],
            line: 5,
        }
    );
    assert!(c.poses[0].reset);
    assert_eq!(c.poses[0].x, Some(0.0));
    let instruments: Vec<Instrument> = c.poses.iter().map(|p| p.instrument).collect();
    assert_eq!(
        instruments,
        [
            Instrument::Lt,
            Instrument::Lt,
            Instrument::Kgm,
            Instrument::Kgm,
            Instrument::Dbb,
            Instrument::Dbb,
            Instrument::LiX,
            Instrument::LiX,
            Instrument::LiY,
            Instrument::LiY,
            Instrument::LiPsi,
            Instrument::LiPsi,
            Instrument::SelfCal,
            Instrument::Circle,
            Instrument::None,
            Instrument::Circle
        ]
    );
    assert_eq!(c.poses[5].r, Some(150.0012));
    assert_eq!(c.poses[7].x, Some(15.0003));
    assert_eq!(c.poses[9].y, Some(25.001));
    assert_eq!(c.poses[11].psi, Some(1.5e-6));
    let s = &c.poses[12];
    assert_eq!(s.follower, [false, true, true, false]);
    assert_eq!(s.q, [2611.0, 2611.414, 788.359, 789.0]);
    assert_eq!(s.line, 16);
    assert_eq!(c.poses[13].r, Some(100.002));
    assert_eq!(c.poses[14].covariates, [Some(19.5), Some(19.75)]);
}

#[test]
fn helpers_give_setups_instruments_and_covariates() {
    let c = parse(VALID).expect("valid");
    let setups = c.setups();
    let ids: Vec<&str> = setups.iter().map(|s| s.id).collect();
    assert_eq!(
        ids,
        ["LT1", "K1", "D1", "LX1", "LY1", "P1", "S1", "C1", "N"]
    );
    assert_eq!(setups[0].reset, Some(0));
    assert_eq!(setups[0].poses, [0, 1]);
    assert_eq!(setups[2].instrument, Instrument::Dbb);
    assert_eq!(setups[2].reset, Some(4));
    assert_eq!(setups[6].reset, None);
    assert_eq!(setups[7].poses, [13, 15]);
    assert_eq!(setups[7].reset, None);
    let circle: Vec<f64> = c.poses_of(Instrument::Circle).map(|p| p.t).collect();
    assert_eq!(circle, [13.0, 15.0]);
    assert_eq!(c.poses_of(Instrument::SelfCal).count(), 1);
    let temp = c.covariate("temp_machine").expect("a covariate");
    assert_eq!(temp.len(), 16);
    assert_eq!(&temp[..3], &[Some(20.5), Some(20.6), Some(20.7)]);
    assert_eq!(temp[3], None);
    assert_eq!(c.covariate("temp_guide2"), None);
    assert_eq!(c.covariate_index("temp_guide1"), Some(1));
}

#[test]
fn columns_in_any_order_spaces_crlf_and_interleaved_comments() {
    let text = "t , psi,r,y,x,follower,f4,f3,f2,f1,q4,q3,q2,q1,reset,instrument,setup ,temp\r\n\
                \r\n\
                0.5, , , 0 , 0 ,,0,0,0,0,789,789,2611,2611,1,lt, A ,\r\n\
                # a comment between rows\r\n\
                0.75,,,-1,2,,0,0,0,0,789,789,2611,2611,0,lt,A,22\r\n";
    let c = parse(text).expect("valid");
    assert_eq!(c.comments, ["a comment between rows"]);
    assert_eq!(c.covariate_names, ["temp"]);
    assert_eq!(c.poses[0].setup, "A");
    assert_eq!(c.poses[0].q, [2611.0, 2611.0, 789.0, 789.0]);
    assert_eq!(c.poses[1].x, Some(2.0));
    assert_eq!(c.poses[1].y, Some(-1.0));
    assert_eq!(c.poses[1].covariates, [Some(22.0)]);
    assert_eq!(c.poses[1].line, 5);
    // Errors name the file's own column numbers, not the canonical ones.
    let bad = text.replace("0.75,,,-1,2", "0.75,,,-1,x2");
    let e = error_at(&bad, Some(5), Some(5));
    assert!(
        matches!(e, CampaignError::BadNumber { ref name, .. } if name == "x"),
        "{e}"
    );
}

#[test]
fn round_trip_of_the_valid_file() {
    let c = parse(VALID).expect("valid");
    let again = parse(&c.to_csv()).expect("written file parses");
    assert_eq!(again, c);
    assert_eq!(again.to_csv(), c.to_csv());
    assert!(c.validate().is_ok());
}

#[test]
fn bad_number_names_line_column_and_text() {
    let e = error_at(&with_field(VALID, 5, 6, "abc"), Some(5), Some(6));
    assert_eq!(
        e.to_string(),
        r#"campaign.csv:5:6 (q2): expected a number, found "abc""#
    );
    assert!(
        matches!(e, CampaignError::BadNumber { ref name, ref text, .. } if name == "q2" && text == "abc")
    );
    // A required number may not be empty.
    let e = error_at(&with_field(VALID, 7, 1, ""), Some(7), Some(1));
    assert!(
        matches!(e, CampaignError::BadNumber { ref name, .. } if name == "t"),
        "{e}"
    );
    // Nor a covariate be text.
    let e = error_at(&with_field(VALID, 4, 18, "warm"), Some(4), Some(18));
    assert!(
        matches!(e, CampaignError::BadNumber { ref name, .. } if name == "temp_machine"),
        "{e}"
    );
    let e = error_at(&with_field(VALID, 4, 9, "1,5"), Some(4), None);
    assert!(
        matches!(
            e,
            CampaignError::WrongFieldCount {
                expected: 19,
                found: 20,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn non_finite_values_are_rejected() {
    for (column, text) in [(14, "NaN"), (5, "inf"), (19, "-infinity"), (9, "nan")] {
        let e = error_at(&with_field(VALID, 5, column, text), Some(5), Some(column));
        assert!(
            matches!(e, CampaignError::NonFinite { text: ref t, .. } if t == text),
            "{e}"
        );
    }
}

#[test]
fn wrong_field_count() {
    let e = error_at(&edit_line(VALID, 6, |l| l.to_owned() + ","), Some(6), None);
    assert!(
        matches!(
            e,
            CampaignError::WrongFieldCount {
                expected: 19,
                found: 20,
                ..
            }
        ),
        "{e}"
    );
    let e = error_at(
        &edit_line(VALID, 8, |l| {
            l.rsplit_once(',')
                .map(|(a, _)| a.to_owned())
                .unwrap_or_default()
        }),
        Some(8),
        None,
    );
    assert!(
        matches!(
            e,
            CampaignError::WrongFieldCount {
                expected: 19,
                found: 18,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn header_errors() {
    let e = error_at(&with_field(VALID, 3, 17, "phi"), Some(3), None);
    assert!(
        matches!(e, CampaignError::MissingColumn { name: "psi", .. }),
        "{e}"
    );
    let e = error_at(&with_field(VALID, 3, 19, "x"), Some(3), Some(19));
    assert!(
        matches!(e, CampaignError::DuplicateColumn { first: 14, .. }),
        "{e}"
    );
    let e = error_at(&with_field(VALID, 3, 19, " "), Some(3), Some(19));
    assert!(matches!(e, CampaignError::EmptyColumnName { .. }), "{e}");
    let e = error_at("", None, None);
    assert!(matches!(e, CampaignError::Empty { .. }), "{e}");
    let e = error_at("# only comments\n\n   \n#\n", None, None);
    assert!(matches!(e, CampaignError::Empty { .. }), "{e}");
    let header_only: String = VALID.lines().take(3).flat_map(|l| [l, "\n"]).collect();
    let e = error_at(&header_only, Some(3), None);
    assert!(matches!(e, CampaignError::NoPoses { .. }), "{e}");
}

#[test]
fn field_syntax_errors() {
    let e = error_at(&with_field(VALID, 5, 3, "LT"), Some(5), Some(3));
    assert!(
        matches!(e, CampaignError::UnknownInstrument { ref text, .. } if text == "LT"),
        "{e}"
    );
    for bad in ["2", "yes", "", "true", "01"] {
        let e = error_at(&with_field(VALID, 5, 4, bad), Some(5), Some(4));
        assert!(matches!(e, CampaignError::BadReset { .. }), "{e}");
    }
    for bad in ["5", "22", "2 3", "x", "0"] {
        let e = error_at(&with_field(VALID, 16, 13, bad), Some(16), Some(13));
        assert!(matches!(e, CampaignError::BadFollower { .. }), "{e}");
    }
}

#[test]
fn time_must_not_decrease() {
    let e = error_at(&with_field(VALID, 9, 1, "6.5"), Some(10), Some(1));
    assert!(
        matches!(e, CampaignError::TimeNotMonotonic { t, previous, previous_line: 9, .. } if t == 6.0 && previous == 6.5),
        "{e}"
    );
    // Equal times are accepted.
    assert!(parse(&with_field(VALID, 9, 1, "6")).is_ok());
}

#[test]
fn reset_errors() {
    // LT1 loses its reset pose: reported at the setup's first row, after the whole file.
    let e = error_at(&with_field(VALID, 4, 4, "0"), Some(4), None);
    assert!(
        matches!(e, CampaignError::MissingReset { ref setup, instrument: Instrument::Lt, .. } if setup == "LT1"),
        "{e}"
    );
    // A second reset pose of D1.
    let text = edit_line(VALID, 8, |l| {
        format!("{l}\n4.5,D1,dbb,1,2611,2611,789,789,0,0,0,0,,,,,,,")
    });
    let e = error_at(&text, Some(9), Some(4));
    assert!(
        matches!(e, CampaignError::DuplicateReset { first_line: 8, .. }),
        "{e}"
    );
    // A reset on an instrument without a reference.
    let e = error_at(&with_field(VALID, 18, 4, "1"), Some(18), Some(4));
    assert!(
        matches!(
            e,
            CampaignError::UnexpectedReset {
                instrument: Instrument::None,
                ..
            }
        ),
        "{e}"
    );
    let e = error_at(&with_field(VALID, 16, 4, "1"), Some(16), Some(4));
    assert!(
        matches!(
            e,
            CampaignError::UnexpectedReset {
                instrument: Instrument::SelfCal,
                ..
            }
        ),
        "{e}"
    );
    // Reset poses measure 0 (or nothing).
    let e = error_at(&with_field(VALID, 4, 15, "0.001"), Some(4), Some(15));
    assert!(
        matches!(e, CampaignError::ResetNotZero { name: "y", .. }),
        "{e}"
    );
    let e = error_at(&with_field(VALID, 8, 16, "150"), Some(8), Some(16));
    assert!(
        matches!(e, CampaignError::ResetNotZero { name: "r", .. }),
        "{e}"
    );
    // A circle may have one reset pose (its pivot), not two.
    let one = with_field(&with_field(VALID, 17, 4, "1"), 17, 16, "0");
    assert_eq!(
        parse(&one).expect("one circle reset").setups()[7].reset,
        Some(13)
    );
    let two = with_field(&with_field(&one, 19, 4, "1"), 19, 16, "");
    let e = error_at(&two, Some(19), Some(4));
    assert!(
        matches!(e, CampaignError::DuplicateReset { first_line: 17, .. }),
        "{e}"
    );
}

#[test]
fn measurement_errors() {
    let e = error_at(&with_field(VALID, 5, 14, ""), Some(5), Some(14));
    assert!(
        matches!(
            e,
            CampaignError::MissingMeasurement {
                name: "x",
                instrument: Instrument::Lt,
                ..
            }
        ),
        "{e}"
    );
    let e = error_at(&with_field(VALID, 9, 16, ""), Some(9), Some(16));
    assert!(
        matches!(
            e,
            CampaignError::MissingMeasurement {
                name: "r",
                instrument: Instrument::Dbb,
                ..
            }
        ),
        "{e}"
    );
    let e = error_at(&with_field(VALID, 17 - 4, 15, ""), Some(13), Some(15));
    assert!(
        matches!(
            e,
            CampaignError::MissingMeasurement {
                name: "y",
                instrument: Instrument::LiY,
                ..
            }
        ),
        "{e}"
    );
    let e = error_at(&with_field(VALID, 15, 17, ""), Some(15), Some(17));
    assert!(
        matches!(
            e,
            CampaignError::MissingMeasurement {
                name: "psi",
                instrument: Instrument::LiPsi,
                ..
            }
        ),
        "{e}"
    );
    let e = error_at(&with_field(VALID, 5, 17, "0.1"), Some(5), Some(17));
    assert!(
        matches!(
            e,
            CampaignError::UnexpectedMeasurement {
                name: "psi",
                instrument: Instrument::Lt,
                ..
            }
        ),
        "{e}"
    );
    let e = error_at(&with_field(VALID, 18, 14, "1"), Some(18), Some(14));
    assert!(
        matches!(
            e,
            CampaignError::UnexpectedMeasurement {
                name: "x",
                instrument: Instrument::None,
                ..
            }
        ),
        "{e}"
    );
    for follower in ["", "2", "3", "14"] {
        let e = error_at(&with_field(VALID, 16, 13, follower), Some(16), Some(13));
        assert!(matches!(e, CampaignError::SelfNeedsFollowers { .. }), "{e}");
    }
    assert!(parse(&with_field(VALID, 16, 13, "1234")).is_ok());
}

#[test]
fn one_instrument_per_setup() {
    let e = error_at(&with_field(VALID, 7, 2, "LT1"), Some(7), Some(3));
    assert!(
        matches!(
            e,
            CampaignError::MixedInstrumentsInSetup {
                instrument: Instrument::Kgm,
                first: Instrument::Lt,
                first_line: 4,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn validate_checks_campaigns_built_in_code() {
    let mut c = parse(VALID).expect("valid");
    c.poses[1].q[2] = f64::NAN;
    let e = c.validate().expect_err("NaN");
    assert!(
        matches!(
            e,
            CampaignError::NonFinite {
                line: 5,
                column: 7,
                ..
            }
        ),
        "{e}"
    );
    let mut c = parse(VALID).expect("valid");
    c.poses[1].covariates.pop();
    assert!(matches!(
        c.validate(),
        Err(CampaignError::WrongFieldCount { line: 5, .. })
    ));
    let mut c = parse(VALID).expect("valid");
    c.poses[0].reset = false;
    assert!(matches!(
        c.validate(),
        Err(CampaignError::MissingReset { line: 4, .. })
    ));
}

#[test]
fn a_byte_order_mark_is_ignored() {
    let c = parse(&format!("\u{feff}{VALID}")).expect("valid with a BOM");
    assert_eq!(c, parse(VALID).expect("valid"));
}

#[test]
fn absurd_numbers_are_refused_and_printed_short() {
    // Line 16 is the self-calibration row: -1e300 in q2 once calibrated "successfully" with
    // every σ infinite.
    let e = error_at(&with_field(VALID, 16, 6, "-1e300"), Some(16), Some(6));
    assert_eq!(
        e.to_string(),
        "campaign.csv:16:6 (q2): -1e300 mm is beyond any machine, expected |q2| <= 100000 mm"
    );
    let digits = format!("1{}", "0".repeat(308));
    let e = error_at(&with_field(VALID, 5, 14, &digits), Some(5), Some(14));
    assert_eq!(
        e.to_string(),
        "campaign.csv:5:14 (x): 1e308 mm is beyond any machine, expected |x| <= 100000 mm"
    );
    let e = error_at(&with_field(VALID, 5, 9, "9e6"), Some(5), Some(9));
    assert!(e.to_string().contains("(f1): 9000000 N is beyond"), "{e}");
    let e = error_at(&with_field(VALID, 5, 18, "-2e10"), Some(5), Some(18));
    // a covariate has no unit: no doubled or trailing space where it would be
    assert_eq!(
        e.to_string(),
        "campaign.csv:5:18 (temp_machine): -20000000000 is beyond any machine, \
         expected |temp_machine| <= 10000000000"
    );
    // A 400-digit number is infinite as an f64: the message shows the text clipped.
    let e = error_at(&with_field(VALID, 5, 5, &"9".repeat(400)), Some(5), Some(5));
    assert!(e.to_string().ends_with("… (400 characters)\""), "{e}");
    for text in ["nan", "NaN", "inf", "-inf", "infinity"] {
        let e = error_at(&with_field(VALID, 5, 7, text), Some(5), Some(7));
        assert!(matches!(e, CampaignError::NonFinite { .. }), "{text}: {e}");
    }
}

#[test]
fn unreachable_poses_are_blamed_on_their_own_line_and_actuator() {
    // q1 = 9000 mm: rods 1 and 4 do not meet; the reset pose (line 4) is blamed itself.
    let e = error_at(&with_field(VALID, 4, 5, "9000"), Some(4), Some(5));
    assert!(
        e.to_string().starts_with(
            "campaign.csv:4:5 (q1): unreachable pose, with q1 = 9000 mm and q4 = 788.9444 mm"
        ),
        "{e}"
    );
    // q4 far off: q4 is blamed.
    let e = error_at(&with_field(VALID, 5, 8, "-5000"), Some(5), Some(8));
    assert!(e.to_string().contains("(q4): unreachable pose"), "{e}");
    // q3 200 mm from what rod 3 needs: q3 is blamed with the figures.
    let e = error_at(&with_field(VALID, 5, 7, "980"), Some(5), Some(7));
    assert!(
        e.to_string().contains(
            "(q3): unreachable pose, rod 3 needs q3 = 777.893 mm at the pose of q1, q4, \
             this is 202.107 mm off, expected within 100 mm"
        ),
        "{e}"
    );
}

#[test]
fn invalid_utf8_names_line_and_byte() {
    let mut bytes = VALID.as_bytes().to_vec();
    let line5 = VALID.lines().take(4).map(|l| l.len() + 1).sum::<usize>();
    bytes[line5 + 3] = 0xff;
    let e = Campaign::parse_bytes(&bytes, FILE).expect_err("not UTF-8");
    assert_eq!(
        e.to_string(),
        format!(
            "campaign.csv:5: invalid UTF-8 at byte {} of the file (byte 4 of the line), \
             expected UTF-8 text",
            line5 + 3
        )
    );
    assert_eq!(e.line(), Some(5));
}

#[test]
fn the_stream_reader_reads_on_after_a_bad_line() {
    use rpkm_core::campaign::CampaignReader;
    let mut reader = CampaignReader::new(FILE);
    let mut poses = Vec::new();
    let mut errors = Vec::new();
    let text = with_field(&with_field(VALID, 5, 4, "true"), 7, 1, "-1");
    for line in text.lines() {
        match reader.read_line(line.as_bytes()) {
            Ok(p) => poses.extend(p),
            Err(e) => errors.push(e.to_string()),
        }
    }
    assert_eq!(
        errors,
        [
            r#"campaign.csv:5:4 (reset): expected 0 or 1, found "true""#,
            "campaign.csv:7:1 (t): time -1 s is before 2 s of line 6; t must be monotonic",
        ]
    );
    assert_eq!(poses.len(), 14);
    assert_eq!(reader.finish(), Ok(()));
    assert_eq!(reader.covariate_names(), ["temp_machine", "temp_guide1"]);
    // The whole-file parser stops at the first of them.
    assert_eq!(
        parse(&text).map_err(|e| e.to_string()),
        Err(errors[0].clone())
    );
}
