// The DBC and NMEA parsers on real files: the opendbc databases and the NMEA
// logs of real receivers in ../shared/data.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "test_data.hpp"
#include "trailnav/drivers/can/dbc.hpp"
#include "trailnav/drivers/gps/nmea.hpp"

namespace {

namespace fs = std::filesystem;
using namespace trailnav;

TEST(Dbc, EveryOpendbcFileParses) {
  int files = 0, with_messages = 0, messages = 0, warnings = 0;
  for (const auto& e : fs::directory_iterator(test::shared_data("can/dbc"))) {
    const auto r = can::load_dbc(e.path().string());
    ASSERT_TRUE(r.dbc) << r.error;
    // One file only imports others (opendbc's preprocessor): no messages of its own.
    with_messages += r.dbc->messages.empty() ? 0 : 1;
    messages += static_cast<int>(r.dbc->messages.size());
    warnings += static_cast<int>(r.dbc->warnings.size());
    ++files;
  }
  EXPECT_EQ(files, 8);
  EXPECT_EQ(with_messages, 7);
  EXPECT_GT(messages, 100);
  // Mazda's CAM_KEEP_ALIVE_1 has a 30-bit signal that runs off its 8 bytes.
  EXPECT_GE(warnings, 1);
  const auto mazda = can::load_dbc(test::shared_data("can/dbc/opendbc_mazda_3_2019.dbc"));
  const can::DbcSignal* broken = mazda.dbc->message("CAM_KEEP_ALIVE_1")->signal("NEW_SIGNAL_4");
  std::array<std::uint8_t, 8> d{};
  double v = 0;
  EXPECT_EQ(can::decode_signal(*broken, d, v), can::SignalError::short_frame);
}

TEST(Dbc, HondaWheelSpeedsAreMotorola15BitSignals) {
  const auto r = can::load_dbc(test::shared_data("can/dbc/opendbc__honda_common.dbc"));
  ASSERT_TRUE(r.dbc) << r.error;
  const can::DbcMessage* m = r.dbc->message(0x1D0);
  ASSERT_NE(m, nullptr);
  EXPECT_EQ(m->name, "WHEEL_SPEEDS");
  const can::DbcSignal* fl = m->signal("WHEEL_SPEED_FL");
  ASSERT_NE(fl, nullptr);
  EXPECT_FALSE(fl->little_endian);
  EXPECT_EQ(fl->length, 15);
  EXPECT_DOUBLE_EQ(fl->factor, 0.01);
  EXPECT_EQ(fl->unit, "kph");
  // FL occupies the first 15 bits from bit 7 of byte 0 down: 0x7FFF<<1 in bytes 0..1.
  std::array<std::uint8_t, 8> data{0x12, 0x34, 0, 0, 0, 0, 0, 0};
  double v = 0;
  ASSERT_EQ(can::decode_signal(*fl, data, v), can::SignalError::none);
  EXPECT_NEAR(v, ((0x1234 >> 1) & 0x7FFF) * 0.01, 1e-9);
  // Every signal of every message round-trips a value in its range.
  for (const can::DbcMessage& msg : r.dbc->messages) {
    for (const can::DbcSignal& s : msg.signals) {
      if (s.length > 52) continue;  // beyond a double's exact integers
      std::array<std::uint8_t, 64> buf{};
      const double raw = s.is_signed ? -3.0 : 5.0;
      const double value = std::min(raw, std::ldexp(1.0, s.length - 1) - 1) * s.factor + s.offset;
      ASSERT_EQ(can::encode_signal(s, value, std::span(buf.data(), static_cast<std::size_t>(msg.size))),
                can::SignalError::none)
          << msg.name << "." << s.name;
      double back = 0;
      ASSERT_EQ(can::decode_signal(s, std::span<const std::uint8_t>(buf.data(), static_cast<std::size_t>(msg.size)), back),
                can::SignalError::none);
      EXPECT_NEAR(back, value, std::abs(s.factor) * 1e-6) << msg.name << "." << s.name;
    }
  }
}

TEST(Dbc, BadInputGetsFileLineAndProblem) {
  auto r = can::parse_dbc("BO_ 100 A: 8 X\n SG_ S : 60|8@1+ (1,0) [0|255] \"\" X\n", "t.dbc");
  ASSERT_TRUE(r.dbc);
  ASSERT_EQ(r.dbc->warnings.size(), 1u);
  EXPECT_NE(r.dbc->warnings[0].find("t.dbc:2"), std::string::npos) << r.dbc->warnings[0];
  EXPECT_NE(r.dbc->warnings[0].find("does not fit"), std::string::npos);
  r = can::parse_dbc("BO_ 100 A: 8 X\n SG_ S : 0|8@1+ (1,0) [0|255 \"\" X\n", "t.dbc");
  ASSERT_FALSE(r.dbc);
  EXPECT_NE(r.error.find("t.dbc:2"), std::string::npos) << r.error;
  r = can::parse_dbc(" SG_ S : 0|8@1+ (1,0) [0|255] \"\" X\n", "t.dbc");
  EXPECT_NE(r.error.find("outside a message"), std::string::npos) << r.error;
  r = can::parse_dbc("BO_ 100 A: 8 X\n SG_ S : 0|8@2+ (1,0) [0|255] \"\" X\n", "t.dbc");
  EXPECT_NE(r.error.find("byte order"), std::string::npos) << r.error;
  // Multiplexed signals parse but refuse to decode.
  r = can::parse_dbc("BO_ 100 A: 8 X\n SG_ Mux M : 0|8@1+ (1,0) [0|255] \"\" X\n SG_ V m1 : 8|8@1+ (1,0) [0|255] \"\" X\n",
                     "t.dbc");
  ASSERT_TRUE(r.dbc) << r.error;
  EXPECT_TRUE(r.dbc->messages[0].multiplexed());
  std::array<std::uint8_t, 8> d{};
  double v = 0;
  EXPECT_EQ(can::decode_signal(r.dbc->messages[0].signals[1], d, v), can::SignalError::multiplexed);
}

TEST(Nmea, RealReceiverLogsParseAndBadChecksumsAreCaught) {
  int files = 0, good = 0, bad_checksum = 0, fixes = 0;
  for (const auto& e : fs::directory_iterator(test::shared_data("nmea"))) {
    if (e.path().extension() != ".log") continue;
    std::ifstream in(e.path());
    std::string line;
    while (std::getline(in, line)) {
      if (line.empty() || line[0] == '#') continue;
      gps::NmeaSentence s;
      const gps::NmeaError err = gps::parse_nmea(line, s);
      if (err == gps::NmeaError::none) {
        ++good;
        if (s.type == gps::SentenceType::gga && s.gga.quality > 0) {
          ++fixes;
          EXPECT_LE(std::abs(s.gga.lat), 90.0);
          EXPECT_LE(std::abs(s.gga.lon), 180.0);
        }
      }
      bad_checksum += err == gps::NmeaError::bad_checksum ? 1 : 0;
    }
    ++files;
  }
  EXPECT_GE(files, 15);
  EXPECT_GT(good, 1000);
  EXPECT_GT(fixes, 100);
  EXPECT_GT(bad_checksum, 0);  // firefly-II carries checksum failures
}

TEST(Nmea, FieldsOfARealSentence) {
  gps::NmeaSentence s;
  ASSERT_EQ(gps::parse_nmea("$GPRMC,005947.00,A,3715.6616,N,12157.6709,W,0.0,0.0,080710,,*2F\r\n", s),
            gps::NmeaError::none);
  EXPECT_EQ(s.type, gps::SentenceType::rmc);
  EXPECT_TRUE(s.rmc.valid);
  EXPECT_NEAR(s.rmc.lat, 37.261026667, 1e-8);
  EXPECT_NEAR(s.rmc.lon, -121.961181667, 1e-8);
  EXPECT_EQ(s.rmc.year, 2010);
  EXPECT_DOUBLE_EQ(s.rmc.time, 47.0 + 59 * 60);
  EXPECT_TRUE(std::isnan(s.rmc.magnetic_variation));
  ASSERT_EQ(gps::parse_nmea("$GPZDA,005947.00,08,07,2010,+00,00*4E", s), gps::NmeaError::none);
  EXPECT_EQ(s.zda.year, 2010);
  EXPECT_EQ(gps::parse_nmea("$GPRMC,005947.00,A,3715.6616,N,12157.6709,W,0.0,0.0,080710,,*2E", s),
            gps::NmeaError::bad_checksum);
  EXPECT_EQ(gps::parse_nmea("GPRMC,1*00", s), gps::NmeaError::no_start);
  EXPECT_EQ(gps::parse_nmea("$GPGGA,1,2", s), gps::NmeaError::missing_checksum);
  EXPECT_EQ(gps::parse_nmea(std::string(200, 'A'), s), gps::NmeaError::too_long);
}

}  // namespace
