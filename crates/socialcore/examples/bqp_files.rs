//! Solves BQP instances from files: first line `n`, then `i j value` lines giving entries
//! of the minimisation matrix `Q` (both triangles listed, or one: the missing mirror is
//! filled in). Prints the objective, nodes, wall and process CPU seconds per file.
//! Run: cargo run --release --example bqp_files -- [--serial] [--limit SECONDS] FILES...
use socialcore::bqp::{solve_bqp, BqpOptions, BqpProblem};
use std::time::{Duration, Instant};

/// Process CPU seconds (user + system) from `/proc/self/stat`; 0 where unavailable.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    let Some(rest) = stat.rsplit(')').next() else {
        return 0.0;
    };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |k: usize| f.get(k).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}

fn read(path: &str) -> BqpProblem {
    let text = std::fs::read_to_string(path).expect("readable file");
    let mut lines = text.lines();
    let n: usize = lines.next().expect("n").trim().parse().expect("n");
    let mut q = vec![0.0; n * n];
    for ln in lines {
        let v: Vec<&str> = ln.split_whitespace().collect();
        if v.len() == 3 {
            let (i, j): (usize, usize) = (v[0].parse().expect("i"), v[1].parse().expect("j"));
            let x: f64 = v[2].parse().expect("value");
            q[i * n + j] = x;
            q[j * n + i] = x;
        }
    }
    BqpProblem::from_row_major(n, q, vec![0.0; n]).expect("valid")
}

fn main() {
    let mut serial = false;
    let mut limit = 600.0;
    let mut files = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--serial" => serial = true,
            "--limit" => limit = args.next().and_then(|v| v.parse().ok()).expect("seconds"),
            _ => files.push(a),
        }
    }
    let (mut wall, mut cpu, mut nodes) = (0.0, 0.0, 0);
    for path in &files {
        let p = read(path);
        let opts = BqpOptions {
            time_limit: Some(Duration::from_secs_f64(limit)),
            parallel: !serial,
            ..BqpOptions::default()
        };
        let (t, c) = (Instant::now(), cpu_seconds());
        let s = solve_bqp(&p, &opts).expect("solve");
        let (dt, dc) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
        wall += dt;
        cpu += dc;
        nodes += s.nodes;
        println!(
            "{path}: obj {} root {:.1} bound {:.1} gap {:.4} nodes {} optimal {} wall {dt:.3}s cpu {dc:.2}s",
            s.objective, s.root_bound, s.bound, s.gap, s.nodes, s.optimal
        );
    }
    println!("total wall {wall:.3}s cpu {cpu:.2}s nodes {nodes}");
}
