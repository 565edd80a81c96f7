//! The template-file reader (a plain PLY cloud or a prepared template) on arbitrary
//! bytes, and a prepared template that parses goes through the core's validation.
#![no_main]
use libfuzzer_sys::fuzz_target;
use ribreg_sim::io::prepared::{parse_template_file, TemplateFile};

fuzz_target!(|bytes: &[u8]| {
    if let Ok(TemplateFile::Prepared(p)) = parse_template_file(bytes) {
        let _ = ribreg_sim::template::prepared::from_file(&p);
    }
});
