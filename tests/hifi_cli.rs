//! `oils hifi`: the open-loop runner from the command line.

mod common;
use common::*;

#[test]
fn hifi_runner_writes_named_columns_at_the_bench_step() {
    let dir = scratch("hifi-cli");
    let profile = dir.join("p.csv");
    std::fs::write(&profile, "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,800,800,800,800,1,1,1,1\n1,400,800,400,800,1,1,1,1\n").unwrap();
    let out_csv = dir.join("out.csv");
    let out = run_oils(&[
        "hifi",
        "--profile",
        profile.to_str().unwrap(),
        "--out",
        out_csv.to_str().unwrap(),
        "--duration-s",
        "2",
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let text_csv = std::fs::read_to_string(&out_csv).unwrap();
    let header: Vec<&str> = text_csv.lines().next().unwrap().split(',').collect();
    for col in [
        "t_s",
        "thrust1_n",
        "thrust2_n",
        "thrust3_n",
        "thrust4_n",
        "gas_pressure_pa",
        "ejected_fuel_kg",
        "ejected_ox_kg",
    ] {
        assert!(header.contains(&col), "missing column {col} in {header:?}");
    }
    let rows: Vec<Vec<f64>> = text_csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert!(
        (199..=201).contains(&rows.len()),
        "{} rows for 2 s at 10 ms",
        rows.len()
    );
    // Engines start: thrust rises from zero towards the command within the first second.
    let t1 = header.iter().position(|c| *c == "thrust1_n").unwrap();
    assert!(rows[0][t1] < 100.0);
    assert!(
        rows[95][t1] > 700.0,
        "engine 1 at {} N after 0.95 s",
        rows[95][t1]
    );

    let bad = run_oils(&[
        "hifi",
        "--profile",
        "/nonexistent.csv",
        "--out",
        out_csv.to_str().unwrap(),
    ]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("nonexistent"));
}
