//! Reading XML database formats (KCD, ARXML, CDD): the document parsed within bounds, children
//! by local name whatever the namespace.

use roxmltree::{Document, Node as XmlNode, ParsingOptions};

use crate::format::Report;
use crate::model::Position;
use crate::parser::ParseError;

/// Parse `text` as XML of at most `nodes_limit` elements (a DTD only when `allow_dtd`: it is
/// never fetched, and its entities count against the limit); malformed XML is a fatal error
/// with its position.
pub(crate) fn parse(
    text: &str,
    allow_dtd: bool,
    nodes_limit: u32,
) -> Result<Document<'_>, ParseError> {
    let options = ParsingOptions {
        allow_dtd,
        nodes_limit,
        ..ParsingOptions::default()
    };
    Document::parse_with_options(text, options).map_err(|e| {
        let pos = e.pos();
        Report::fatal(
            Position {
                line: pos.row,
                column: pos.col,
            },
            format!("not well-formed XML: {e}"),
        )
    })
}

/// The first child element named `tag`.
pub(crate) fn child<'a, 'input>(n: XmlNode<'a, 'input>, tag: &str) -> Option<XmlNode<'a, 'input>> {
    n.children()
        .find(|c| c.is_element() && c.tag_name().name() == tag)
}

/// Every child element named `tag`.
pub(crate) fn children<'a, 'input>(
    n: XmlNode<'a, 'input>,
    tag: &'a str,
) -> impl Iterator<Item = XmlNode<'a, 'input>> + 'a {
    n.children()
        .filter(move |c| c.is_element() && c.tag_name().name() == tag)
}
