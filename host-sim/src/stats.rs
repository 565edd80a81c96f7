//! Summary statistics and the paired t-test of `ribreg eval`.

/// Mean, population SD and max of a sample (zeros for an empty one).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Summary {
    /// Mean.
    pub mean: f64,
    /// Standard deviation (population, ddof = 0).
    pub sd: f64,
    /// Largest value.
    pub max: f64,
    /// Sample size.
    pub n: usize,
}

impl Summary {
    /// Summary of `values`.
    pub fn of(values: &[f64]) -> Summary {
        let n = values.len();
        if n == 0 {
            return Summary::default();
        }
        let mean = values.iter().sum::<f64>() / n as f64;
        let sd = (values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n as f64).sqrt();
        Summary {
            mean,
            sd,
            max: values.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            n,
        }
    }
}

/// Paired two-sided t-test of `a` against `b` (same length ≥ 2): the t statistic of the
/// differences `a − b` and its p-value (as scipy's `ttest_rel`). `None` when the
/// differences have no spread.
pub fn paired_t_test(a: &[f64], b: &[f64]) -> Option<(f64, f64)> {
    let n = a.len().min(b.len());
    if n < 2 {
        return None;
    }
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    let mean = d.iter().sum::<f64>() / n as f64;
    let var = d.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1) as f64;
    if var <= 0.0 || !var.is_finite() {
        return None;
    }
    let t = mean / (var / n as f64).sqrt();
    Some((t, t_two_sided_p(t, (n - 1) as f64)))
}

/// Two-sided p-value of Student's t with `df` degrees of freedom:
/// `I_{df/(df+t²)}(df/2, 1/2)`, the regularised incomplete beta function.
pub fn t_two_sided_p(t: f64, df: f64) -> f64 {
    incomplete_beta(df / (df + t * t), 0.5 * df, 0.5)
}

/// Regularised incomplete beta `I_x(a, b)` by Lentz's continued fraction (Numerical
/// Recipes §6.4), accurate to ~1e-14 relative.
fn incomplete_beta(x: f64, a: f64, b: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    let front = ln_front.exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        front * beta_cf(x, a, b) / a
    } else {
        1.0 - front * beta_cf(1.0 - x, b, a) / b
    }
}

fn beta_cf(x: f64, a: f64, b: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < TINY {
        d = TINY;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..300 {
        let m = f64::from(m);
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 + aa * d;
        d = if d.abs() < TINY { TINY } else { d };
        c = 1.0 + aa / c;
        c = if c.abs() < TINY { TINY } else { c };
        d = 1.0 / d;
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 + aa * d;
        d = if d.abs() < TINY { TINY } else { d };
        c = 1.0 + aa / c;
        c = if c.abs() < TINY { TINY } else { c };
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// ln Γ(x) for x > 0 (Lanczos, g = 7, n = 9; ~1e-15 relative).
fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection.
        return (std::f64::consts::PI / (std::f64::consts::PI * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let t = x + 7.5;
    let mut s = C[0];
    for (i, c) in C.iter().enumerate().skip(1) {
        s += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + s.ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_scipy() {
        // scipy 1.17.1: stats.ttest_rel(a, b) and 2 * stats.t.sf(t, df).
        let a = [3.1, 2.4, 5.6, 4.4, 3.3, 2.9, 6.1, 4.0];
        let b = [4.0, 2.2, 7.1, 5.9, 3.0, 4.4, 7.7, 5.5];
        let (t, p) = paired_t_test(&a, &b).unwrap();
        assert!((t - -3.527_668_414_752_787_5).abs() < 1e-12);
        assert!((p - 0.009_627_924_725_379_822).abs() < 1e-12);
        for (t, df, want) in [
            (2.5, 7.0, 0.040_992_218_585_752_89),
            (0.3, 3.0, 0.783_763_292_039_919),
            (10.0, 40.0, 1.931_311_700_411_550_6e-12),
        ] {
            let p = t_two_sided_p(t, df);
            assert!(
                (p - want).abs() <= 1e-10 * want.max(1e-3),
                "t {t} df {df}: {p} vs {want}"
            );
        }
        assert!(paired_t_test(&[1.0, 2.0], &[0.0, 1.0]).is_none());
        assert!(paired_t_test(&[1.0], &[0.0]).is_none());
    }

    #[test]
    fn summary() {
        let s = Summary::of(&[1.0, 2.0, 3.0, 6.0]);
        assert_eq!((s.mean, s.max, s.n), (3.0, 6.0, 4));
        assert!((s.sd - 1.870_828_693_386_970_7).abs() < 1e-12);
        assert_eq!(Summary::of(&[]), Summary::default());
    }
}
