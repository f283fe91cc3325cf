// UTF-8 validation for text read from files. Every string facedyn reads may end up in a JSON
// report (session check --json, take.json, metrics), and JSON text must be UTF-8 (RFC 8259
// section 8.1; nlohmann::json throws type_error.316 when asked to dump anything else), so the
// readers refuse invalid UTF-8 where it enters, with the line it is on, rather than letting a
// later dump fail far from the file.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace facedyn {

// True if `text` is well-formed UTF-8 (Unicode 15, table 3-7: no overlong forms, no surrogates
// U+D800..U+DFFF, nothing above U+10FFFF). On false, *bad_offset (if given) is the byte offset of
// the first ill-formed sequence.
bool IsValidUtf8(std::string_view text, size_t* bad_offset = nullptr);

// `text` with every byte that is not part of a well-formed sequence written as \xNN, for error
// messages that quote a file (a parser's own message, a line that did not parse): the message
// stays UTF-8 and still shows the byte.
std::string EscapeInvalidUtf8(std::string_view text);

}  // namespace facedyn
