#include "core/message.h"

#include <cstdio>
#include <sstream>

namespace fluorosim {

std::string excerpt(std::string_view text, size_t maxChars) {
    std::string out;
    size_t i = 0, shown = 0;
    for (; i < text.size() && shown < maxChars; ++shown) {
        const auto c = static_cast<unsigned char>(text[i]);
        if (c == '\n') out += "\\n";
        else if (c == '\t') out += "\\t";
        else if (c < 0x20 || c == 0x7f) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\x%02x", c);
            out += buf;
        } else {
            // A whole UTF-8 sequence counts as one character.
            size_t len = 1;
            while (i + len < text.size() && (static_cast<unsigned char>(text[i + len]) & 0xC0) == 0x80 && len < 4) ++len;
            out.append(text.substr(i, len));
            i += len;
            continue;
        }
        ++i;
    }
    if (i < text.size()) out += "... (" + std::to_string(text.size()) + " characters)";
    return out;
}

std::string messageNumber(double v) {
    std::ostringstream os;
    os << v;
    return os.str();
}

}  // namespace fluorosim
