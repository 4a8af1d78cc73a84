//! The expressions of written effects ([`super::written`]): `a * sin(2*pi*q4/60)`, parsed
//! once into a stack program and evaluated at each pose with its exact derivatives by the
//! effect's parameters (forward-mode dual numbers: every value carries its gradient).
//!
//! A small parser of our own rather than an expression crate: the maintained one that
//! differentiates (`exmex`) has no derivative of `abs`, `signum`, `min` and `max`, spells
//! `sign` and `pi` otherwise, and its parse errors carry no position, which a bad effect file
//! must name (docs/effects.md).
//!
//! Grammar: numbers (`2`, `0.5`, `1e-3`), names, `pi`, `+ - * / ^` (`^` binds tighter than a
//! sign and to the right: `-a^2` is `-(a^2)`), parentheses and the functions `sin cos exp ln
//! sqrt abs sign tanh` (one argument) and `min max` (two). Two more read a covariate along
//! the campaign's time rather than the row alone ([`super::memory`]): `rate(NAME)`, the
//! column's rate per second, and `lag(NAME, TAU)` with `TAU` a parameter or a number
//! (seconds). The resolver is asked for them by their text (`rate(temp_machine)`,
//! `lag(temp_machine,tau)`).

/// A function an expression may call.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Func {
    Sin,
    Cos,
    Exp,
    Ln,
    Sqrt,
    Abs,
    Sign,
    Tanh,
    Min,
    Max,
}

impl Func {
    /// Every function with its spelling.
    pub const ALL: [(&'static str, Func); 10] = [
        ("sin", Func::Sin),
        ("cos", Func::Cos),
        ("exp", Func::Exp),
        ("ln", Func::Ln),
        ("sqrt", Func::Sqrt),
        ("abs", Func::Abs),
        ("sign", Func::Sign),
        ("tanh", Func::Tanh),
        ("min", Func::Min),
        ("max", Func::Max),
    ];

    fn arity(self) -> usize {
        match self {
            Func::Min | Func::Max => 2,
            _ => 1,
        }
    }
}

/// What a name of an expression stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Name {
    /// Variable `k` of the pose (a campaign column or derived covariate).
    Var(usize),
    /// Parameter `k` of the effect.
    Param(usize),
    /// Lag `slot` of the effect (`lag(NAME, TAU)`), its time constant parameter `tau` (None:
    /// a number).
    Lag { slot: usize, tau: Option<usize> },
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Op {
    Const(f64),
    Var(usize),
    Param(usize),
    Lag { slot: usize, tau: Option<usize> },
    Neg,
    Add,
    Sub,
    Mul,
    Div,
    Pow,
    Call(Func),
}

/// A parsed expression: a stack program.
#[derive(Clone, Debug, PartialEq)]
pub struct Program {
    ops: Vec<Op>,
}

/// Why an expression does not parse, at character `at` (0-based) of its text.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{kind}")]
pub struct ExprError {
    pub at: usize,
    pub kind: ExprErrorKind,
}

/// What is wrong with an expression.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ExprErrorKind {
    #[error("syntax error: {0}")]
    Syntax(String),
    #[error("unknown variable or parameter `{0}`")]
    UnknownName(String),
    #[error("unknown function `{0}` (known: sin cos exp ln sqrt abs sign tanh min max)")]
    UnknownFunction(String),
    #[error("`{name}` takes {expected} argument(s), found {found}")]
    Arity {
        name: String,
        expected: usize,
        found: usize,
    },
}

#[derive(Clone, Debug, PartialEq)]
enum Token {
    Num(f64),
    Ident(String),
    Sym(char),
    End,
}

struct Parser<'a> {
    chars: Vec<char>,
    pos: usize,
    /// Start of the current token.
    start: usize,
    token: Token,
    resolve: &'a dyn Fn(&str) -> Option<Name>,
    ops: Vec<Op>,
}

/// Parses `text`; `resolve` says what each name stands for (`pi` and the functions are the
/// language's own).
pub fn parse(text: &str, resolve: &dyn Fn(&str) -> Option<Name>) -> Result<Program, ExprError> {
    let mut p = Parser {
        chars: text.chars().collect(),
        pos: 0,
        start: 0,
        token: Token::End,
        resolve,
        ops: Vec::new(),
    };
    p.advance()?;
    if p.token == Token::End {
        return Err(p.error(ExprErrorKind::Syntax("empty expression".into())));
    }
    p.expression(0)?;
    if p.token != Token::End {
        return Err(p.error(ExprErrorKind::Syntax(format!(
            "unexpected {}",
            describe(&p.token)
        ))));
    }
    Ok(Program { ops: p.ops })
}

fn describe(t: &Token) -> String {
    match t {
        Token::Num(v) => format!("number {v}"),
        Token::Ident(s) => format!("name `{s}`"),
        Token::Sym(c) => format!("`{c}`"),
        Token::End => "end of expression".into(),
    }
}

/// Binding power of a binary operator (left, right), or None.
fn infix(c: char) -> Option<(u8, u8, Op)> {
    match c {
        '+' => Some((1, 2, Op::Add)),
        '-' => Some((1, 2, Op::Sub)),
        '*' => Some((3, 4, Op::Mul)),
        '/' => Some((3, 4, Op::Div)),
        // right-associative, above a sign
        '^' => Some((8, 7, Op::Pow)),
        _ => None,
    }
}

/// Binding power of a sign's operand: above `*`, below `^`.
const SIGN_POWER: u8 = 5;

impl Parser<'_> {
    fn error(&self, kind: ExprErrorKind) -> ExprError {
        ExprError {
            at: self.start,
            kind,
        }
    }

    fn advance(&mut self) -> Result<(), ExprError> {
        while self.chars.get(self.pos).is_some_and(|c| c.is_whitespace()) {
            self.pos += 1;
        }
        self.start = self.pos;
        let Some(&c) = self.chars.get(self.pos) else {
            self.token = Token::End;
            return Ok(());
        };
        if c.is_ascii_digit() || c == '.' {
            return self.number();
        }
        if c.is_alphabetic() || c == '_' {
            let end = (self.pos..self.chars.len())
                .find(|&i| !(self.chars[i].is_alphanumeric() || self.chars[i] == '_'))
                .unwrap_or(self.chars.len());
            self.token = Token::Ident(self.chars[self.pos..end].iter().collect());
            self.pos = end;
            return Ok(());
        }
        if "+-*/^(),".contains(c) {
            self.pos += 1;
            // `**` is a power too
            if c == '*' && self.chars.get(self.pos) == Some(&'*') {
                self.pos += 1;
                self.token = Token::Sym('^');
            } else {
                self.token = Token::Sym(c);
            }
            return Ok(());
        }
        Err(self.error(ExprErrorKind::Syntax(format!("unexpected character `{c}`"))))
    }

    fn number(&mut self) -> Result<(), ExprError> {
        let mut end = self.pos;
        let digits = |i: usize, chars: &[char]| {
            (i..chars.len())
                .find(|&j| !chars[j].is_ascii_digit())
                .unwrap_or(chars.len())
        };
        end = digits(end, &self.chars);
        if self.chars.get(end) == Some(&'.') {
            end = digits(end + 1, &self.chars);
        }
        if matches!(self.chars.get(end), Some('e' | 'E')) {
            let mut e = end + 1;
            if matches!(self.chars.get(e), Some('+' | '-')) {
                e += 1;
            }
            if self.chars.get(e).is_some_and(char::is_ascii_digit) {
                end = digits(e, &self.chars);
            }
        }
        let text: String = self.chars[self.pos..end].iter().collect();
        let value = text
            .parse::<f64>()
            .map_err(|_| self.error(ExprErrorKind::Syntax(format!("`{text}` is not a number"))))?;
        self.token = Token::Num(value);
        self.pos = end;
        Ok(())
    }

    fn expect(&mut self, c: char) -> Result<(), ExprError> {
        if self.token == Token::Sym(c) {
            return self.advance();
        }
        Err(self.error(ExprErrorKind::Syntax(format!(
            "expected `{c}`, found {}",
            describe(&self.token)
        ))))
    }

    /// An expression whose operators bind at least as tightly as `min_power`.
    fn expression(&mut self, min_power: u8) -> Result<(), ExprError> {
        self.operand()?;
        while let Token::Sym(c) = self.token {
            let Some((left, right, op)) = infix(c) else {
                break;
            };
            if left < min_power {
                break;
            }
            self.advance()?;
            self.expression(right)?;
            self.ops.push(op);
        }
        Ok(())
    }

    fn operand(&mut self) -> Result<(), ExprError> {
        match self.token.clone() {
            Token::Num(v) => {
                self.ops.push(Op::Const(v));
                self.advance()
            }
            Token::Sym('-') => {
                self.advance()?;
                self.expression(SIGN_POWER)?;
                self.ops.push(Op::Neg);
                Ok(())
            }
            Token::Sym('+') => {
                self.advance()?;
                self.expression(SIGN_POWER)
            }
            Token::Sym('(') => {
                self.advance()?;
                self.expression(0)?;
                self.expect(')')
            }
            Token::Ident(name) => self.name(&name),
            other => Err(self.error(ExprErrorKind::Syntax(format!(
                "expected a number, a name or `(`, found {}",
                describe(&other)
            )))),
        }
    }

    fn name(&mut self, name: &str) -> Result<(), ExprError> {
        let at = self.start;
        self.advance()?;
        if self.token == Token::Sym('(') {
            return self.call(name, at);
        }
        let op = if name == "pi" {
            Op::Const(std::f64::consts::PI)
        } else {
            match (self.resolve)(name) {
                Some(Name::Var(k)) => Op::Var(k),
                Some(Name::Param(k)) => Op::Param(k),
                Some(Name::Lag { .. }) | None => {
                    return Err(ExprError {
                        at,
                        kind: ExprErrorKind::UnknownName(name.to_owned()),
                    })
                }
            }
        };
        self.ops.push(op);
        Ok(())
    }

    fn call(&mut self, name: &str, at: usize) -> Result<(), ExprError> {
        if name == "rate" || name == "lag" {
            return self.memory(name, at);
        }
        let Some(func) = Func::ALL.iter().find(|f| f.0 == name).map(|f| f.1) else {
            return Err(ExprError {
                at,
                kind: ExprErrorKind::UnknownFunction(name.to_owned()),
            });
        };
        self.advance()?;
        let mut found = 0;
        if self.token != Token::Sym(')') {
            loop {
                self.expression(0)?;
                found += 1;
                if self.token != Token::Sym(',') {
                    break;
                }
                self.advance()?;
            }
        }
        self.expect(')')?;
        if found != func.arity() {
            return Err(ExprError {
                at,
                kind: ExprErrorKind::Arity {
                    name: name.to_owned(),
                    expected: func.arity(),
                    found,
                },
            });
        }
        self.ops.push(Op::Call(func));
        Ok(())
    }

    /// `rate(NAME)` or `lag(NAME, TAU)`, the current token the `(`.
    fn memory(&mut self, name: &str, at: usize) -> Result<(), ExprError> {
        self.advance()?;
        let Token::Ident(column) = self.token.clone() else {
            return Err(self.error(ExprErrorKind::Syntax(format!(
                "`{name}` reads a covariate column by its name, found {}",
                describe(&self.token)
            ))));
        };
        self.advance()?;
        let text = if name == "lag" {
            self.expect(',')?;
            let negative = self.token == Token::Sym('-');
            if negative {
                self.advance()?;
            }
            let tau = match self.token.clone() {
                Token::Ident(p) if !negative => p,
                Token::Num(v) => format!("{}", if negative { -v } else { v }),
                other => {
                    return Err(self.error(ExprErrorKind::Syntax(format!(
                        "`lag`'s time constant is a parameter or a number of seconds, found {}",
                        describe(&other)
                    ))))
                }
            };
            self.advance()?;
            format!("lag({column},{tau})")
        } else {
            format!("rate({column})")
        };
        self.expect(')')?;
        let op = match (self.resolve)(&text) {
            Some(Name::Var(k)) => Op::Var(k),
            Some(Name::Lag { slot, tau }) => Op::Lag { slot, tau },
            _ => {
                return Err(ExprError {
                    at,
                    kind: ExprErrorKind::UnknownName(text),
                })
            }
        };
        self.ops.push(op);
        Ok(())
    }
}

impl Program {
    /// The value at variables `vars`, lags `lags` (value and derivative by its time constant,
    /// per slot, at `theta`) and parameters `theta`, its gradient by the parameters written to
    /// `grad` (`theta.len()` entries). `stack` is scratch space kept between calls.
    pub fn eval(
        &self,
        (vars, lags): (&[f64], &[(f64, f64)]),
        theta: &[f64],
        grad: &mut [f64],
        stack: &mut Vec<f64>,
    ) -> f64 {
        // each stack entry: the value, then its gradient
        let w = 1 + theta.len();
        stack.clear();
        for op in &self.ops {
            match *op {
                Op::Const(c) => push(stack, w, c, None),
                Op::Var(k) => push(stack, w, vars[k], None),
                Op::Param(k) => push(stack, w, theta[k], Some(k)),
                Op::Lag { slot, tau } => {
                    let (value, slope) = lags[slot];
                    push(stack, w, value, None);
                    if let Some(k) = tau {
                        let n = stack.len();
                        stack[n - w + 1 + k] = slope;
                    }
                }
                Op::Neg => {
                    let n = stack.len();
                    stack[n - w..].iter_mut().for_each(|v| *v = -*v);
                }
                Op::Call(f) if f.arity() == 1 => {
                    let n = stack.len();
                    unary(f, &mut stack[n - w..]);
                }
                binary => {
                    let n = stack.len();
                    let (a, b) = stack[n - 2 * w..].split_at_mut(w);
                    apply(binary, a, b);
                    stack.truncate(n - w);
                }
            }
        }
        grad.copy_from_slice(&stack[1..w]);
        stack[0]
    }
}

fn push(stack: &mut Vec<f64>, w: usize, value: f64, unit: Option<usize>) {
    let n = stack.len();
    stack.resize(n + w, 0.0);
    stack[n] = value;
    if let Some(k) = unit {
        stack[n + 1 + k] = 1.0;
    }
}

/// `a` becomes f(a), value and gradient.
fn unary(f: Func, a: &mut [f64]) {
    let x = a[0];
    let (value, slope) = match f {
        Func::Sin => (x.sin(), x.cos()),
        Func::Cos => (x.cos(), -x.sin()),
        Func::Exp => (x.exp(), x.exp()),
        Func::Ln => (x.ln(), 1.0 / x),
        Func::Sqrt => (x.sqrt(), 0.5 / x.sqrt()),
        Func::Abs => (x.abs(), x.signum()),
        // sign(0) is 0, as the covariates' directions read it
        Func::Sign => (if x == 0.0 { 0.0 } else { x.signum() }, 0.0),
        Func::Tanh => (x.tanh(), 1.0 - x.tanh() * x.tanh()),
        Func::Min | Func::Max => unreachable!("binary functions are applied by `apply`"),
    };
    a[0] = value;
    a[1..].iter_mut().for_each(|g| *g *= slope);
}

/// `a` becomes `a op b`, value and gradient.
fn apply(op: Op, a: &mut [f64], b: &[f64]) {
    let (x, y) = (a[0], b[0]);
    // d(a op b) = da · sa + db · sb
    let (value, sa, sb) = match op {
        Op::Add => (x + y, 1.0, 1.0),
        Op::Sub => (x - y, 1.0, -1.0),
        Op::Mul => (x * y, y, x),
        Op::Div => (x / y, 1.0 / y, -x / (y * y)),
        Op::Pow => {
            let v = x.powf(y);
            // ln x only where the exponent varies: a constant power of a negative base is fine
            let sb = if b[1..].iter().any(|g| *g != 0.0) {
                v * x.ln()
            } else {
                0.0
            };
            (v, y * x.powf(y - 1.0), sb)
        }
        Op::Call(Func::Min) => (
            x.min(y),
            f64::from(u8::from(x <= y)),
            f64::from(u8::from(x > y)),
        ),
        Op::Call(Func::Max) => (
            x.max(y),
            f64::from(u8::from(x >= y)),
            f64::from(u8::from(x < y)),
        ),
        _ => unreachable!("not a binary operation: {op:?}"),
    };
    a[0] = value;
    for (ga, gb) in a[1..].iter_mut().zip(&b[1..]) {
        // a zero gradient times an infinite slope is no change, not a NaN
        let da = if *ga == 0.0 { 0.0 } else { *ga * sa };
        let db = if *gb == 0.0 { 0.0 } else { *gb * sb };
        *ga = da + db;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(s: &str) -> Option<Name> {
        match s {
            "q" => Some(Name::Var(0)),
            "t" => Some(Name::Var(1)),
            "a" => Some(Name::Param(0)),
            "c" => Some(Name::Param(1)),
            _ => None,
        }
    }

    fn eval(text: &str, vars: &[f64], theta: &[f64]) -> (f64, Vec<f64>) {
        let p = parse(text, &names).expect("parses");
        let mut g = vec![0.0; theta.len()];
        let v = p.eval((vars, &[]), theta, &mut g, &mut Vec::new());
        (v, g)
    }

    /// The value of the constant expression `text` is `want` (to rounding).
    fn close(text: &str, want: f64) {
        let got = eval(text, &[], &[]).0;
        assert!(
            (got - want).abs() <= 1e-12 * want.abs(),
            "{text} = {got}, want {want}"
        );
    }

    #[test]
    fn precedence_and_signs() {
        close("1 + 2 * 3", 7.0);
        close("-2^2", -4.0);
        close("2^3^2", 512.0);
        close("(1 + 2) * 3 - 4 / 2", 7.0);
        close("2 * -3", -6.0);
        close("8 - 2 - 1", 5.0);
        close("1e-3 * 2.5E2", 0.25);
        close("max(1, min(5, 3))", 3.0);
    }

    /// Every function and operator: the gradient against central differences.
    #[test]
    fn gradients_match_finite_differences() {
        let texts = [
            "a * sin(2*pi*q/60) + c * cos(2*pi*q/60)",
            "exp(a*t) / (1 + c^2) - ln(2 + a) * sqrt(3 + c*q)",
            "abs(a - 0.3) * sign(q) + tanh(c*t) + a^c + min(a, c*q) - max(a*c, t)",
            "-a^2 * q ** 2 / c",
        ];
        let (vars, theta) = ([2.5, -0.7], [0.45, 1.3]);
        for text in texts {
            let (_, g) = eval(text, &vars, &theta);
            for k in 0..2 {
                let h = 1e-6;
                let mut up = theta;
                up[k] += h;
                let mut down = theta;
                down[k] -= h;
                let fd = (eval(text, &vars, &up).0 - eval(text, &vars, &down).0) / (2.0 * h);
                assert!(
                    (g[k] - fd).abs() < 1e-7 * (1.0 + fd.abs()),
                    "{text}: ∂/∂θ{k} {} vs {fd}",
                    g[k]
                );
            }
        }
    }

    #[test]
    fn errors_say_where() {
        let err = |s: &str| parse(s, &names).expect_err(s);
        assert_eq!(err("a * foo").at, 4);
        assert!(matches!(err("a * foo").kind, ExprErrorKind::UnknownName(_)));
        assert!(matches!(
            err("sinh(a)").kind,
            ExprErrorKind::UnknownFunction(_)
        ));
        assert!(matches!(err("min(a)").kind, ExprErrorKind::Arity { .. }));
        assert_eq!(err("a * (q + 1").at, 10);
        assert_eq!(err("a $ 2").at, 2);
        assert_eq!(err("a q").at, 2);
        assert!(matches!(err("").kind, ExprErrorKind::Syntax(_)));
        assert_eq!(err("1.2.3").at, 3);
    }
}
