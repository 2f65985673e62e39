//! `fresco view <ws | model.glb>`: serves a workspace's report (with its viewer) or a GLB in
//! the viewer on 127.0.0.1 at a free port (or `--port`), prints the address and serves until
//! Ctrl-C. Only files inside the workspace (or the one GLB) are served, read-only; hidden
//! files and paths leaving the folder are refused.

use std::io::{BufRead, BufReader, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Component, Path, PathBuf};

use anyhow::{Context as _, bail};
use clap::Args;

#[derive(Args, Debug)]
pub struct ViewArgs {
    /// A workspace of `fresco run` (its report.html) or a .glb file.
    pub target: PathBuf,
    /// Port on 127.0.0.1 (0: a free one).
    #[arg(long, default_value_t = 0)]
    pub port: u16,
}

/// What is served.
enum Site {
    /// A workspace folder: `/` is report.html (or the viewer of model.glb), files under it.
    Workspace(PathBuf),
    /// One GLB: `/` is the viewer, `/model.glb` the file.
    Glb(PathBuf),
}

fn content_type(path: &Path) -> &'static str {
    match path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .as_deref()
    {
        Some("html") => "text/html; charset=utf-8",
        Some("json") => "application/json",
        Some("glb") => "model/gltf-binary",
        Some("png") => "image/png",
        Some("jpg" | "jpeg") => "image/jpeg",
        Some("svg") => "image/svg+xml",
        Some("js") => "text/javascript",
        Some("txt") => "text/plain; charset=utf-8",
        _ => "application/octet-stream",
    }
}

/// The file under `root` that URL path `url` names, if it stays inside and is not hidden.
fn resolve(root: &Path, url: &str) -> Option<PathBuf> {
    let path = url.split(['?', '#']).next().unwrap_or("");
    let decoded = percent_decode(path)?;
    let mut out = root.to_path_buf();
    for part in Path::new(decoded.trim_start_matches('/')).components() {
        match part {
            Component::Normal(name) if !name.to_string_lossy().starts_with('.') => out.push(name),
            Component::CurDir => {}
            _ => return None,
        }
    }
    let canonical = out.canonicalize().ok()?;
    (canonical.starts_with(root) && canonical.is_file()).then_some(canonical)
}

fn percent_decode(s: &str) -> Option<String> {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// The response body and type for `url`, or `None` for 404.
fn respond(site: &Site, url: &str) -> Option<(Vec<u8>, &'static str)> {
    let path = url.split(['?', '#']).next().unwrap_or("");
    match site {
        Site::Glb(glb) => match path {
            "/" | "/index.html" => Some((
                crate::report::viewer_page(
                    &glb.file_name().unwrap_or_default().to_string_lossy(),
                    "/model.glb",
                )
                .into_bytes(),
                "text/html; charset=utf-8",
            )),
            "/model.glb" => std::fs::read(glb).ok().map(|b| (b, "model/gltf-binary")),
            _ => None,
        },
        Site::Workspace(ws) => {
            if path == "/" || path == "/index.html" {
                let report = ws.join("report.html");
                if report.is_file() {
                    return std::fs::read(report)
                        .ok()
                        .map(|b| (b, "text/html; charset=utf-8"));
                }
                if ws.join("model.glb").is_file() {
                    return Some((
                        crate::report::viewer_page("model.glb", "/model.glb").into_bytes(),
                        "text/html; charset=utf-8",
                    ));
                }
                return None;
            }
            let file = resolve(ws, path)?;
            std::fs::read(&file).ok().map(|b| (b, content_type(&file)))
        }
    }
}

fn handle(site: &Site, stream: TcpStream) -> std::io::Result<()> {
    let mut reader = BufReader::new(stream.try_clone()?);
    let mut request = String::new();
    reader.read_line(&mut request)?;
    // Headers are read and ignored.
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line)? == 0 || line == "\r\n" || line == "\n" {
            break;
        }
    }
    let mut parts = request.split_whitespace();
    let (method, url) = (parts.next().unwrap_or(""), parts.next().unwrap_or("/"));
    let mut stream = stream;
    let (status, body, kind) = if method != "GET" && method != "HEAD" {
        ("405 Method Not Allowed", b"only GET".to_vec(), "text/plain")
    } else {
        match respond(site, url) {
            Some((body, kind)) => ("200 OK", body, kind),
            None => ("404 Not Found", b"not found".to_vec(), "text/plain"),
        }
    };
    write!(
        stream,
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    if method != "HEAD" {
        stream.write_all(&body)?;
    }
    stream.flush()
}

pub fn run(args: ViewArgs, ctx: &crate::Context) -> anyhow::Result<serde_json::Value> {
    let target = args
        .target
        .canonicalize()
        .with_context(|| format!("{}: no such workspace or file", args.target.display()))?;
    let site = if target.is_dir() {
        if !target.join("report.html").is_file() && !target.join("model.glb").is_file() {
            bail!(
                "{} has neither report.html nor model.glb: run `fresco run <photos> -o {}` first",
                args.target.display(),
                args.target.display()
            );
        }
        Site::Workspace(target)
    } else if target
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"))
    {
        Site::Glb(target)
    } else {
        bail!(
            "{}: expected a workspace folder or a .glb file",
            args.target.display()
        );
    };
    let listener = TcpListener::bind(("127.0.0.1", args.port))
        .with_context(|| format!("cannot listen on 127.0.0.1:{}", args.port))?;
    let addr = listener.local_addr()?;
    // The address goes to stdout even with --quiet: it is what the command is for.
    println!("fresco view: http://{addr}/ (Ctrl-C stops)");
    let _ = std::io::stdout().flush();
    let _ = ctx;
    let site = std::sync::Arc::new(site);
    for stream in listener.incoming() {
        let Ok(stream) = stream else { continue };
        let site = site.clone();
        std::thread::spawn(move || {
            if let Err(e) = handle(&site, stream) {
                tracing::debug!("fresco view: {e}");
            }
        });
    }
    Ok(serde_json::Value::Null)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_visible_files_inside_the_root_are_resolved() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().canonicalize().unwrap();
        std::fs::create_dir_all(root.join("sub")).unwrap();
        std::fs::write(root.join("sub").join("a.png"), b"x").unwrap();
        std::fs::write(root.join(".hidden"), b"x").unwrap();
        assert_eq!(
            resolve(&root, "/sub/a.png"),
            Some(root.join("sub").join("a.png"))
        );
        assert_eq!(
            resolve(&root, "/sub/%61.png?x=1"),
            Some(root.join("sub").join("a.png"))
        );
        assert_eq!(resolve(&root, "/../etc/passwd"), None);
        assert_eq!(resolve(&root, "/sub/../../x"), None);
        assert_eq!(resolve(&root, "/.hidden"), None);
        assert_eq!(resolve(&root, "/sub"), None);
    }
}
