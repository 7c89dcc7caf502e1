//! Reading XML database formats (ARXML, CDD): children by local name, whatever the namespace.

use roxmltree::Node as XmlNode;

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
