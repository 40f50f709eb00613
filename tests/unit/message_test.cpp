// excerpt(): input echoed into error messages stays one short line.
#include <gtest/gtest.h>

#include <string>

#include "core/message.h"

namespace fluorosim {
namespace {

TEST(Excerpt, ShortTextIsUnchanged) {
    EXPECT_EQ(excerpt("5 parsec"), "5 parsec");
    EXPECT_EQ(excerpt(""), "");
    EXPECT_EQ(excerpt(std::string(80, 'a')), std::string(80, 'a'));
}

TEST(Excerpt, LongTextIsCutWithItsLength) {
    const std::string huge(50 << 20, 'x');
    const std::string e = excerpt(huge);
    EXPECT_EQ(e, std::string(80, 'x') + "... (52428800 characters)");
    EXPECT_EQ(excerpt("abcdef", 3), "abc... (6 characters)");
}

TEST(Excerpt, ControlCharactersAreEscapedSoTheMessageStaysOneLine) {
    EXPECT_EQ(excerpt("a\nb\tc\rd"), "a\\nb\\tc\\x0dd");
    EXPECT_EQ(excerpt(std::string("nul\0end", 7)), "nul\\x00end");
}

TEST(Excerpt, CutsNeverSplitAUtf8Sequence) {
    // "µ" is two bytes; three of them cut after two characters keep both whole.
    EXPECT_EQ(excerpt("µµµ", 2), "µµ... (6 characters)");
}

}  // namespace
}  // namespace fluorosim
