//! One line per error, each cause once.

use std::error::Error;

/// `error` and its causes as one line, `outer: cause: root cause`, leaving out a cause whose text
/// the line already holds (an error that names its source in its own message, as `"{path}:
/// {source}"` does, would otherwise print the source twice), and any line breaks.
pub fn error_line(error: &(dyn Error + 'static)) -> String {
    let mut line = one_line(&error.to_string());
    let mut cause = error.source();
    while let Some(e) = cause {
        let text = one_line(&e.to_string());
        if !text.is_empty() && !line.contains(&text) {
            line.push_str(": ");
            line.push_str(&text);
        }
        cause = e.source();
    }
    line
}

fn one_line(text: &str) -> String {
    let parts: Vec<&str> = text.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
    parts.join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fmt;

    #[derive(Debug)]
    struct Named {
        path: &'static str,
        source: std::io::Error,
    }

    impl fmt::Display for Named {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(f, "{}: {}", self.path, self.source)
        }
    }

    impl Error for Named {
        fn source(&self) -> Option<&(dyn Error + 'static)> {
            Some(&self.source)
        }
    }

    #[derive(Debug)]
    struct Context {
        what: String,
        source: Box<dyn Error + 'static>,
    }

    impl fmt::Display for Context {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str(&self.what)
        }
    }

    impl Error for Context {
        fn source(&self) -> Option<&(dyn Error + 'static)> {
            Some(self.source.as_ref())
        }
    }

    fn missing() -> std::io::Error {
        std::io::Error::new(std::io::ErrorKind::NotFound, "No such file or directory (os error 2)")
    }

    #[test]
    fn a_cause_the_message_already_names_prints_once() {
        let e = Context {
            what: "/x is not a run directory".into(),
            source: Box::new(Named {
                path: "/x/config.toml",
                source: missing(),
            }),
        };
        assert_eq!(
            error_line(&e),
            "/x is not a run directory: /x/config.toml: No such file or directory (os error 2)"
        );
    }

    #[test]
    fn causes_that_add_something_are_all_kept_in_order() {
        let e = Context {
            what: "training".into(),
            source: Box::new(Context {
                what: "step 5".into(),
                source: Box::new(missing()),
            }),
        };
        assert_eq!(
            error_line(&e),
            "training: step 5: No such file or directory (os error 2)"
        );
    }

    #[test]
    fn a_multi_line_message_becomes_one_line() {
        let e = Context {
            what: "bad config\n  at line 3\n".into(),
            source: Box::new(missing()),
        };
        let line = error_line(&e);
        assert!(!line.contains('\n'), "{line}");
        assert_eq!(line, "bad config at line 3: No such file or directory (os error 2)");
    }
}
