//! pbrt's tokens: bare words (directives, numbers, `true`/`false`),
//! quoted strings, `[` and `]`, with `#` comments to the end of the line.
//! Every token keeps its file, line and column ([`Loc`]), so every later
//! error names them.

use crate::Result;
pub use crate::mitsuba::xml::Loc;
use std::path::PathBuf;
use std::sync::Arc;

/// What a token is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A directive name, a number or a bare `true`/`false`.
    Bare,
    /// A quoted string (its text without the quotes, escapes resolved).
    Quoted,
    /// `[`.
    Open,
    /// `]`.
    Close,
}

/// One token and where it starts.
#[derive(Debug, Clone, PartialEq)]
pub struct Token {
    /// Its kind.
    pub kind: Kind,
    /// Its text (without quotes for [`Kind::Quoted`]).
    pub text: String,
    /// Where it starts.
    pub loc: Loc,
}

impl Token {
    /// The token as written, for messages.
    pub fn shown(&self) -> String {
        match self.kind {
            Kind::Quoted => format!("\"{}\"", self.text),
            _ => self.text.clone(),
        }
    }
}

/// A tokenizer over one file's text with one token of look-ahead.
#[derive(Debug)]
pub struct Lexer<'t> {
    text: &'t str,
    pos: usize,
    line: usize,
    column: usize,
    file: Arc<PathBuf>,
    peeked: Option<Token>,
}

impl<'t> Lexer<'t> {
    /// A tokenizer of `text`, which messages call `file`.
    pub fn new(text: &'t str, file: Arc<PathBuf>) -> Self {
        Self {
            text,
            pos: 0,
            line: 1,
            column: 1,
            file,
            peeked: None,
        }
    }

    /// The current position.
    pub fn loc(&self) -> Loc {
        Loc {
            file: self.file.clone(),
            line: self.line,
            column: self.column,
        }
    }

    fn bump(&mut self) -> Option<char> {
        let c = self.text[self.pos..].chars().next()?;
        self.pos += c.len_utf8();
        if c == '\n' {
            self.line += 1;
            self.column = 1;
        } else {
            self.column += 1;
        }
        Some(c)
    }

    fn peek_char(&self) -> Option<char> {
        self.text[self.pos..].chars().next()
    }

    /// The next token without taking it; `None` at the end of the file.
    pub fn peek(&mut self) -> Result<Option<&Token>> {
        if self.peeked.is_none() {
            self.peeked = self.scan()?;
        }
        Ok(self.peeked.as_ref())
    }

    /// Takes the next token; `None` at the end of the file.
    pub fn next_token(&mut self) -> Result<Option<Token>> {
        match self.peeked.take() {
            Some(t) => Ok(Some(t)),
            None => self.scan(),
        }
    }

    /// Takes the next token, or an error naming `what` was expected.
    pub fn expect(&mut self, what: &str) -> Result<Token> {
        let at = self.loc();
        self.next_token()?
            .ok_or_else(|| at.error(format!("expected {what}, found the end of the file")))
    }

    /// Takes a quoted string, or an error naming `what` it should be.
    pub fn string(&mut self, what: &str) -> Result<Token> {
        let t = self.expect(what)?;
        if t.kind != Kind::Quoted {
            return Err(t.loc.error(format!(
                "expected {what} (a quoted string), found {}",
                t.shown()
            )));
        }
        Ok(t)
    }

    /// Takes a bare number.
    pub fn number(&mut self, what: &str) -> Result<f32> {
        let t = self.expect(what)?;
        number_of(&t, what)
    }

    fn scan(&mut self) -> Result<Option<Token>> {
        // Whitespace and comments.
        loop {
            match self.peek_char() {
                Some(c) if c.is_whitespace() => {
                    self.bump();
                }
                Some('#') => {
                    while let Some(c) = self.peek_char() {
                        if c == '\n' {
                            break;
                        }
                        self.bump();
                    }
                }
                _ => break,
            }
        }
        let loc = self.loc();
        let Some(c) = self.bump() else {
            return Ok(None);
        };
        let (kind, text) = match c {
            '[' => (Kind::Open, "[".to_owned()),
            ']' => (Kind::Close, "]".to_owned()),
            '"' => {
                let mut s = String::new();
                loop {
                    match self.bump() {
                        None | Some('\n') => {
                            return Err(
                                loc.error("unterminated string (no closing quote on its line)")
                            );
                        }
                        Some('"') => break,
                        Some('\\') => {
                            let e = self.bump();
                            s.push(match e {
                                Some('n') => '\n',
                                Some('t') => '\t',
                                Some('b') => '\u{8}',
                                Some('f') => '\u{c}',
                                Some('r') => '\r',
                                Some(other) => other,
                                None => {
                                    return Err(
                                        loc.error("unterminated string at the end of the file")
                                    );
                                }
                            });
                        }
                        Some(other) => s.push(other),
                    }
                }
                (Kind::Quoted, s)
            }
            first => {
                let mut s = String::from(first);
                while let Some(c) = self.peek_char() {
                    if c.is_whitespace() || matches!(c, '[' | ']' | '"' | '#') {
                        break;
                    }
                    s.push(c);
                    self.bump();
                }
                (Kind::Bare, s)
            }
        };
        Ok(Some(Token { kind, text, loc }))
    }
}

/// A bare token read as a finite number.
pub fn number_of(t: &Token, what: &str) -> Result<f32> {
    if t.kind != Kind::Bare {
        return Err(t
            .loc
            .error(format!("expected {what} (a number), found {}", t.shown())));
    }
    match t.text.parse::<f64>() {
        Ok(v) if v.is_finite() && v.abs() <= f32::MAX as f64 => Ok(v as f32),
        Ok(_) => Err(t.loc.error(format!("{what}: {} is out of range", t.text))),
        Err(_) => Err(t
            .loc
            .error(format!("expected {what} (a number), found {}", t.shown()))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tokens(text: &str) -> Result<Vec<(Kind, String, usize, usize)>> {
        let mut lx = Lexer::new(text, Arc::new(PathBuf::from("t.pbrt")));
        let mut out = Vec::new();
        while let Some(t) = lx.next_token()? {
            out.push((t.kind, t.text, t.loc.line, t.loc.column));
        }
        Ok(out)
    }

    #[test]
    fn tokens_keep_line_and_column() {
        let t = tokens("LookAt 0 1 2 # comment \"x\"\n  Shape \"sphere\" \"float radius\" [ 2.5 ]")
            .expect("test input");
        assert_eq!(t[0], (Kind::Bare, "LookAt".into(), 1, 1));
        assert_eq!(t[3], (Kind::Bare, "2".into(), 1, 12));
        assert_eq!(t[4], (Kind::Bare, "Shape".into(), 2, 3));
        assert_eq!(t[5], (Kind::Quoted, "sphere".into(), 2, 9));
        assert_eq!(t[7], (Kind::Open, "[".into(), 2, 33));
        assert_eq!(t[8], (Kind::Bare, "2.5".into(), 2, 35));
        assert_eq!(t.len(), 10);
    }

    #[test]
    fn broken_strings_are_errors_at_their_start() {
        let e = tokens("Shape\n   \"sphere")
            .expect_err("unterminated")
            .to_string();
        assert!(
            e.contains("t.pbrt:2:4") && e.contains("unterminated"),
            "{e}"
        );
        let e = tokens("Shape \"sph\nere\"")
            .expect_err("newline")
            .to_string();
        assert!(e.contains("t.pbrt:1:7"), "{e}");
        let t = tokens(r#""a\"b\\c""#).expect("escapes");
        assert_eq!(t[0].1, "a\"b\\c");
    }

    #[test]
    fn numbers_must_be_finite() {
        let mut lx = Lexer::new("1e400 abc 2", Arc::new(PathBuf::from("t.pbrt")));
        let e = lx.number("x").expect_err("huge").to_string();
        assert!(
            e.contains("t.pbrt:1:1") && e.contains("out of range"),
            "{e}"
        );
        let e = lx.number("x").expect_err("word").to_string();
        assert!(e.contains("t.pbrt:1:7"), "{e}");
        assert_eq!(lx.number("x").expect("two"), 2.0);
    }
}
