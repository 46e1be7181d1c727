//! The files the viewer serves from inside the binary: its page, and the vendored
//! renderer with its licence (vendor/gsplat/README.md says which release and checksum).
//! Nothing is fetched from the network when the page runs.

pub struct Asset {
    pub path: &'static str,
    pub content_type: &'static str,
    pub body: &'static [u8],
}

pub const ASSETS: [Asset; 5] = [
    Asset {
        path: "/",
        content_type: "text/html; charset=utf-8",
        body: include_bytes!("page/index.html"),
    },
    Asset {
        path: "/app.js",
        content_type: "text/javascript; charset=utf-8",
        body: include_bytes!("page/app.js"),
    },
    Asset {
        path: "/orbit.js",
        content_type: "text/javascript; charset=utf-8",
        body: include_bytes!("page/orbit.js"),
    },
    Asset {
        path: "/vendor/gsplat/index.es.js",
        content_type: "text/javascript; charset=utf-8",
        body: include_bytes!("vendor/gsplat/index.es.js"),
    },
    Asset {
        path: "/vendor/gsplat/LICENSE",
        content_type: "text/plain; charset=utf-8",
        body: include_bytes!("vendor/gsplat/LICENSE"),
    },
];

pub fn find(path: &str) -> Option<&'static Asset> {
    let path = if path == "/index.html" { "/" } else { path };
    ASSETS.iter().find(|a| a.path == path)
}
