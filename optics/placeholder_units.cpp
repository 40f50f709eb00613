// Keeps the optics library non-empty until its first model lands; removed then.
namespace fluorosim::optics {
int opticsLibraryVersion() { return 1; }
}  // namespace fluorosim::optics
