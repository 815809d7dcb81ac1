//! The page, compiled into the binary: plain HTML, CSS and JavaScript with no build step and
//! nothing fetched from elsewhere (a clinic's control PC may have no internet).

/// The page.
pub const HTML: &str = include_str!("../page/index.html");
/// Its script: status over the WebSocket, the plot, the 3-D view, the buttons, the tuning form.
pub const JS: &str = include_str!("../page/console.js");
/// Its style.
pub const CSS: &str = include_str!("../page/console.css");
