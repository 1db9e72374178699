//! A session report's tables as a GitHub-style renderer shows them.

#![allow(dead_code)]

/// Every table of `markdown` (a block of `|` lines) renders as a table in a CommonMark renderer with
/// GitHub's table extension, with as many columns in each row as in its header.
pub fn assert_tables_render(markdown: &str) {
    use pulldown_cmark::{Event, Options, Parser, Tag, TagEnd};
    let mut blocks = 0;
    let mut in_block = false;
    for line in markdown.lines() {
        let pipe = line.trim_start().starts_with('|');
        if pipe && !in_block {
            blocks += 1;
        }
        in_block = pipe;
    }
    let mut tables = 0;
    let mut header_cells = 0;
    let mut row_cells = 0;
    let mut in_head = false;
    for event in Parser::new_ext(markdown, Options::ENABLE_TABLES) {
        match event {
            Event::Start(Tag::Table(_)) => tables += 1,
            Event::Start(Tag::TableHead) => {
                in_head = true;
                header_cells = 0;
            }
            Event::End(TagEnd::TableHead) => in_head = false,
            Event::Start(Tag::TableRow) => row_cells = 0,
            Event::Start(Tag::TableCell) if in_head => header_cells += 1,
            Event::Start(Tag::TableCell) => row_cells += 1,
            Event::End(TagEnd::TableRow) => {
                assert_eq!(
                    row_cells, header_cells,
                    "a row's cells against its header's"
                );
            }
            _ => {}
        }
    }
    assert!(blocks >= 1, "no table: {markdown}");
    assert_eq!(
        tables, blocks,
        "tables that render of the `|` blocks\n{markdown}"
    );
}
